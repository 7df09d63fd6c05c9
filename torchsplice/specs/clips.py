"""Clip rules of a dataset spec: :class:`RoleRule` (which clips take which role) and
:func:`clip_stem` (the clip name a file stem, file name or path stands for).
"""

from __future__ import annotations

import fnmatch
from dataclasses import dataclass
from pathlib import PurePath

__all__ = ["RoleRule", "clip_stem"]


@dataclass(frozen=True)
class RoleRule:
    """One ``[[clips.role]]`` rule: clips it matches get ``role``.

    Attributes:
        role: ``"locomotion"``, ``"action"`` or ``"both"``.
        names: shell globs on the clip name (case-insensitive); empty matches every name.
        labels: ``((key, (value, ...)), ...)`` sorted by key: every key's label must be one of
            its values.
    """

    role: str
    names: tuple[str, ...] = ()
    labels: tuple[tuple[str, tuple[str, ...]], ...] = ()

    def matches(self, clip_name: str, labels: dict[str, str]) -> bool:
        """Whether a clip with this name and these labels falls under the rule."""
        lower = clip_name.lower()
        if self.names and not any(fnmatch.fnmatchcase(lower, g.lower()) for g in self.names):
            return False
        return all(labels.get(key) in values for key, values in self.labels)


def clip_stem(name: str) -> str:
    """A clip name from a stem, file name or path (``.bvh`` dropped)."""
    base = PurePath(str(name)).name
    return base[:-4] if base.lower().endswith(".bvh") else base
