"""Pictures: stick-figure previews and alignment plots (matplotlib, no display needed)."""
