"""Choosing the plain-locomotion reference of an action, for the ``cpmc`` method."""

from __future__ import annotations

from typing import Iterable

from ..specs import DatasetSpec

__all__ = ["find_reference"]


def find_reference(action: str, labels: dict[str, str], candidates: Iterable[tuple[str, str, dict[str, str]]],
                   spec: DatasetSpec) -> str | None:
    """The reference clip for ``action`` (its name), or ``None``.

    ``candidates`` are ``(name, role, labels)`` of the clips available. The spec's
    ``[clips.reference]`` rule gives the labels the reference must carry; among the clips with
    role ``locomotion`` or ``both`` that carry them, the first by name is chosen.
    """
    want = spec.reference_labels(labels)
    if want is None:
        return None
    hits = sorted(n for n, role, lab in candidates
                  if n != action and role in ("locomotion", "both") and all(lab.get(k) == v for k, v in want.items()))
    return hits[0] if hits else None
