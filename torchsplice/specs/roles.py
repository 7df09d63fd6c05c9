"""Skeleton roles: a dataset spec bound to one skeleton, as integer joint indices.

:class:`SkeletonRoles` is the domain type every stage reads (splicing, kinematics, evaluation);
:func:`bind_roles` makes it from a spec's joint names (what :meth:`DatasetSpec.bind` calls),
checking the hierarchy. Joint pairs are ``(left, right)``; the up axis is 0, 1 or 2 (x, y, z).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

from ..core.errors import SpecError
from ..core.skeleton import Skeleton
from .vocabulary import AXES, OPTIONAL_PAIRS, PAIRS

__all__ = ["chain", "SkeletonRoles", "bind_roles", "landmark_indices", "is_ancestor"]


@dataclass(frozen=True)
class SkeletonRoles:
    """A spec bound to one skeleton: integer joint indices by role.

    Attributes:
        root: the joint carrying the world trajectory.
        pelvis: the lowest upper-body joint (splicing edits its local rotation).
        spine: the chain from the pelvis upward.
        hips, knees, feet, shoulders: ``(left, right)`` indices.
        toes, hands: ``(left, right)`` or ``None``.
        head: index or ``None``.
        upper_body, lower_body: sorted, disjoint, together every joint.
        up_axis: 0, 1 or 2 (x, y, z).
        units: the spec's length unit (see :data:`UNITS`).
    """

    root: int
    pelvis: int
    spine: tuple[int, ...]
    hips: tuple[int, int]
    knees: tuple[int, int]
    feet: tuple[int, int]
    shoulders: tuple[int, int]
    toes: tuple[int, int] | None
    hands: tuple[int, int] | None
    head: int | None
    upper_body: tuple[int, ...]
    lower_body: tuple[int, ...]
    up_axis: int
    units: str


# --------------------------------------------------------------------------------------------
# binding
# --------------------------------------------------------------------------------------------
def landmark_indices(roles: SkeletonRoles, landmarks) -> list[int]:
    """Joint indices of the named roles (e.g. ``("root", "knees")``), pairs expanded (left, right)."""
    out = []
    for name in landmarks:
        v = getattr(roles, name, None)
        if v is None or name in ("upper_body", "lower_body", "up_axis", "units"):
            raise ValueError(f"unknown or absent landmark role {name!r}")
        out += list(v) if isinstance(v, tuple) else [v]
    return out


def bind_roles(spec, sk: Skeleton) -> SkeletonRoles:
    """Indices of the joints a :class:`~torchsplice.specs.DatasetSpec` ``spec`` names in ``sk``,
    with the hierarchy checks of :meth:`DatasetSpec.bind` (whose joint names and ``where`` it
    reads; this module does not import the spec)."""

    def idx(key, name):
        if name not in sk.names:
            raise SpecError(
                f"{spec.where}: [joints] {key} names joint {name!r}, which the skeleton "
                f"does not have; its joints: {', '.join(sk.names)}"
            )
        return sk.names.index(name)

    def pair(key):
        value = getattr(spec, key)
        return None if value is None else (idx(key, value[0]), idx(key, value[1]))

    roles = dict(
        root=idx("root", spec.root),
        pelvis=idx("pelvis", spec.pelvis),
        spine=tuple(idx("spine", n) for n in spec.spine),
        head=None if spec.head is None else idx("head", spec.head),
        **{k: pair(k) for k in (*PAIRS, *OPTIONAL_PAIRS)},
    )
    _check_hierarchy(spec, sk, roles)
    upper, lower = _body_split(spec, sk, roles["pelvis"], idx)
    return SkeletonRoles(**roles, upper_body=upper, lower_body=lower, up_axis=AXES[spec.up_axis], units=spec.units)


def chain(parents: tuple[int, ...], top: int, bottom: int) -> list[int]:
    """Joints from ``top`` down to ``bottom`` (both included), or ``[]`` when ``bottom`` does
    not hang below ``top``."""
    out, j = [], bottom
    while j >= 0:
        out.append(j)
        if j == top:
            return out[::-1]
        j = parents[j]
    return []


def is_ancestor(parents: tuple[int, ...], a: int, b: int) -> bool:
    """Whether joint ``a`` is ``b`` or one of its ancestors."""
    while b >= 0:
        if b == a:
            return True
        b = parents[b]
    return False


def _check_hierarchy(spec, sk: Skeleton, r: dict) -> None:
    """Refuse roles the hierarchy contradicts (each problem named with its joints)."""
    anc = functools.partial(is_ancestor, sk.parents)
    name = sk.names

    def fail(problem):
        raise SpecError(f"{spec.where}: [joints] {problem}")

    if not anc(r["root"], r["pelvis"]):
        fail(f"root {name[r['root']]!r} must be the pelvis {name[r['pelvis']]!r} or one of its ancestors")
    for key in ("hips", "knees", "feet"):
        for j in r[key]:
            if anc(r["pelvis"], j):
                fail(
                    f"{key}: {name[j]!r} lies below the pelvis {name[r['pelvis']]!r}; the pelvis must "
                    "be an upper-body joint, not an ancestor of the legs"
                )
            if key == "hips" and not anc(r["root"], j):
                fail(f"hips: {name[j]!r} is not below the root {name[r['root']]!r}")
    chains = [("hips", "knees"), ("knees", "feet"), ("feet", "toes"), ("shoulders", "hands")]
    for upper, lower in chains:
        if r[upper] is None or r[lower] is None:
            continue
        for side in (0, 1):
            a, b = r[upper][side], r[lower][side]
            if a == b or not anc(a, b):
                fail(f"{lower}: {name[b]!r} must lie below {upper} {name[a]!r}")
    for a, b in zip(r["spine"], r["spine"][1:]):
        if a == b or not anc(a, b):
            fail(f"spine: {name[b]!r} must lie below {name[a]!r} (list the spine from the pelvis upward)")


def _body_split(spec, sk: Skeleton, pelvis: int, idx) -> tuple[tuple[int, ...], tuple[int, ...]]:
    """Upper- and lower-body joint sets: explicit lists, or the pelvis's subtree and the rest."""
    every = set(range(sk.num_joints))
    upper = set(idx("upper_body", n) for n in spec.upper_body) if spec.upper_body is not None else None
    lower = set(idx("lower_body", n) for n in spec.lower_body) if spec.lower_body is not None else None
    if upper is None:
        upper = set(sk.descendants(pelvis)) if lower is None else every - lower
    if lower is None:
        lower = every - upper
    both, missing = upper & lower, every - upper - lower
    if both or missing:
        bad = sorted(both or missing)
        what = "in both upper_body and lower_body" if both else "in neither upper_body nor lower_body"
        raise SpecError(f"{spec.where}: [joints] joints {[sk.names[j] for j in bad]} are {what}")
    if pelvis not in upper:
        raise SpecError(f"{spec.where}: [joints] upper_body must contain the pelvis {sk.names[pelvis]!r}")
    return tuple(sorted(upper)), tuple(sorted(lower))
