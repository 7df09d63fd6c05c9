"""The words of a dataset spec: clip roles, length units, axes, joint-role keys and the keys of
a guessed spec's record, shared by every module of :mod:`torchsplice.specs` (this one imports
none of them).
"""

from __future__ import annotations

__all__ = [
    "ROLES",
    "UNITS",
    "GENERIC",
    "SHIPPED_PACKAGE",
    "AXES",
    "PAIRS",
    "OPTIONAL_PAIRS",
    "SECTION_KEYS",
    "GUESS_KEYS",
    "GUESS_SINGLE",
    "one_line",
]

ROLES = ("locomotion", "action", "both")
"""Clip roles: lower-body source, upper-body source, or either."""

UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001, "in": 0.0254, "ft": 0.3048, "cmu": 0.0254 / 0.45, "unknown": None}
"""Length units a spec may name, with metres per unit (``None`` for ``"unknown"``).

``"cmu"`` is the CMU Graphics Lab unit (the ASF ``length 0.45``: 1 unit = 1/0.45 inch).
"""

GENERIC = "generic"
"""The shipped spec that guesses its joints (see :func:`~torchsplice.specs.guess_spec`)."""
SHIPPED_PACKAGE = "torchsplice.datasets_spec"
"""The package holding the shipped specs (``*.toml``)."""

AXES = {"x": 0, "y": 1, "z": 2}
"""Up-axis names and their indices."""
PAIRS = ("hips", "knees", "feet", "shoulders")
"""Joint roles every spec names as ``(left, right)`` pairs."""
OPTIONAL_PAIRS = ("toes", "hands")
"""Joint-pair roles a spec may leave out."""

SECTION_KEYS = {
    "dataset": {"name", "description", "up_axis", "units", "files"},
    "joints": {"root", "pelvis", "spine", "head", "upper_body", "lower_body", "guess", *PAIRS, *OPTIONAL_PAIRS},
    "clips": {"pattern", "default_role", "role", "reference", "ground_truth"},
}
"""The keys each table of a spec file may hold."""

GUESS_KEYS = ("root", "pelvis", "spine", "head", "left_leg", "right_leg", "left_arm", "right_arm", "skipped")
"""Keys of a guessed spec's record (:meth:`DatasetSpec.guessed_roles`), in order."""
GUESS_SINGLE = ("root", "pelvis", "head")
"""Keys of that record that name one joint (the others name a list)."""


def one_line(exc: BaseException) -> str:
    """An exception's message on one line."""
    return " ".join(str(exc).split())
