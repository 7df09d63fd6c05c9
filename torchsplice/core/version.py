"""The package version, stated once (pyproject.toml reads the same number)."""

__version__ = "0.1.0"
