"""The skeleton: joint names, hierarchy, rest offsets, BVH channel layout and end sites.

Joints are indexed ``0..J-1`` in topological order: ``parents[0] == -1`` (the single BVH
root) and ``parents[j] < j`` for every other joint. Offsets are each joint's rest translation
in its parent's frame, in the file's units, as a ``(J, 3)`` float64 tensor.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import torch

from .errors import MotionError

__all__ = ["Skeleton", "ROTATION_CHANNELS", "POSITION_CHANNELS", "SCALE_RTOL", "hierarchy_levels", "channel_columns"]

ROTATION_CHANNELS = ("Xrotation", "Yrotation", "Zrotation")
POSITION_CHANNELS = ("Xposition", "Yposition", "Zposition")
SCALE_RTOL = 0.2
"""Two skeletons whose :meth:`Skeleton.size` differ by more than this share of the larger are
two skeletons (other units, or another body), whatever else they share."""


@functools.lru_cache(maxsize=64)
def hierarchy_levels(parents: tuple[int, ...]) -> tuple[tuple[int, ...], ...]:
    """Joints grouped by depth: ``levels[d]`` holds the joints ``d`` bones below a root.

    Forward kinematics computes one level at a time, so its Python loop runs over the
    hierarchy's depth, not over joints.
    """
    depth: list[int] = []
    for j, p in enumerate(parents):
        if p >= j:
            raise ValueError(f"parents must be topologically ordered, joint {j} has parent {p}")
        depth.append(0 if p < 0 else depth[p] + 1)
    levels: list[list[int]] = [[] for _ in range(max(depth, default=-1) + 1)]
    for j, d in enumerate(depth):
        levels[d].append(j)
    return tuple(tuple(level) for level in levels)


@dataclass(frozen=True, eq=False)
class Skeleton:
    """A joint hierarchy with its rest offsets and BVH channel layout.

    Attributes:
        names: ``J`` unique joint names.
        parents: ``J`` parent indices, ``-1`` for the root (joint 0 only), topological order.
        offsets: ``(J, 3)`` float64 rest translations in the parent's frame (file units).
        channels: per joint, the BVH channel names in file order, e.g.
            ``("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation")``.
        end_site_parents: for each BVH ``End Site``, the joint it hangs from.
        end_site_offsets: ``(E, 3)`` float64 end-site offsets in that joint's frame.
    """

    names: tuple[str, ...]
    parents: tuple[int, ...]
    offsets: torch.Tensor
    channels: tuple[tuple[str, ...], ...]
    end_site_parents: tuple[int, ...] = ()
    end_site_offsets: torch.Tensor = field(default_factory=lambda: torch.zeros(0, 3, dtype=torch.float64))

    def __post_init__(self):
        object.__setattr__(self, "names", tuple(str(n) for n in self.names))
        object.__setattr__(self, "parents", tuple(int(p) for p in self.parents))
        object.__setattr__(self, "channels", tuple(tuple(str(c) for c in ch) for ch in self.channels))
        object.__setattr__(self, "end_site_parents", tuple(int(p) for p in self.end_site_parents))
        offsets = torch.as_tensor(self.offsets, dtype=torch.float64).reshape(-1, 3)
        object.__setattr__(self, "offsets", offsets)
        ends = torch.as_tensor(self.end_site_offsets, dtype=torch.float64).reshape(-1, 3)
        object.__setattr__(self, "end_site_offsets", ends)
        J = len(self.names)
        if J == 0:
            raise ValueError("a skeleton needs at least one joint")
        if len(set(self.names)) != J:
            dup = sorted({n for n in self.names if self.names.count(n) > 1})
            raise ValueError(f"joint names must be unique, repeated: {', '.join(dup)}")
        if len(self.parents) != J or offsets.shape[0] != J or len(self.channels) != J:
            raise ValueError(
                f"names ({J}), parents ({len(self.parents)}), offsets ({offsets.shape[0]}) and "
                f"channels ({len(self.channels)}) must have one entry per joint"
            )
        if self.parents[0] != -1 or any(p < 0 for p in self.parents[1:]):
            raise ValueError("joint 0 must be the only root (parent -1)")
        far = [j for j, p in enumerate(self.parents) if p >= J]
        if far:
            raise ValueError(
                f"joint {self.names[far[0]]!r} has parent {self.parents[far[0]]}, "
                f"but the skeleton has joints 0..{J - 1}"
            )
        hierarchy_levels(self.parents)  # validates the order
        for name, ch in zip(self.names, self.channels):
            bad = [c for c in ch if c not in ROTATION_CHANNELS + POSITION_CHANNELS]
            if bad or len(set(ch)) != len(ch):
                raise ValueError(f"joint {name!r} has invalid channels {list(ch)}")
            rot = [c for c in ch if c in ROTATION_CHANNELS]
            if len(rot) not in (0, 3):
                raise ValueError(f"joint {name!r} must have 0 or 3 rotation channels, has {rot}")
        if len(self.end_site_parents) != ends.shape[0]:
            raise ValueError("end_site_parents and end_site_offsets must have the same length")
        bad_end = [p for p in self.end_site_parents if not 0 <= p < J]
        if bad_end:
            raise ValueError(f"an End Site hangs from joint {bad_end[0]}, but the skeleton has joints 0..{J - 1}")

    # -- lookups ---------------------------------------------------------------------------
    @property
    def num_joints(self) -> int:
        """Number of joints ``J``."""
        return len(self.names)

    def index(self, name: str) -> int:
        """Index of the joint called ``name``; a clear error listing the joints otherwise."""
        try:
            return self.names.index(name)
        except ValueError:
            raise MotionError(f"unknown joint {name!r}; the skeleton has: {', '.join(self.names)}") from None

    def indices(self, names) -> list[int]:
        """Indices of several joints, in the order given."""
        return [self.index(n) for n in names]

    def children(self, j: int) -> list[int]:
        """Indices of the joints whose parent is ``j``."""
        return [c for c, p in enumerate(self.parents) if p == j]

    def descendants(self, j: int) -> list[int]:
        """``j`` and every joint below it, in index order."""
        inside = [False] * self.num_joints
        inside[j] = True
        for c in range(j + 1, self.num_joints):
            inside[c] = inside[self.parents[c]]
        return [c for c in range(self.num_joints) if inside[c]]

    @property
    def levels(self) -> tuple[tuple[int, ...], ...]:
        """Joints grouped by depth (see :func:`hierarchy_levels`)."""
        return hierarchy_levels(self.parents)

    def rotation_order(self, j: int) -> str | None:
        """Euler order of joint ``j``'s rotation channels (e.g. ``"ZXY"``), ``None`` if it has none."""
        rot = [c[0] for c in self.channels[j] if c in ROTATION_CHANNELS]
        return "".join(rot) if rot else None

    @property
    def translation_animated(self) -> tuple[bool, ...]:
        """Per joint: whether the BVH file animates its translation (has position channels)."""
        return tuple(any(c in POSITION_CHANNELS for c in ch) for ch in self.channels)

    @property
    def has_joint_translations(self) -> bool:
        """Whether any joint other than the root has animated translation."""
        return any(self.translation_animated[1:])

    # -- geometry --------------------------------------------------------------------------
    def rest_positions(self) -> tuple[torch.Tensor, torch.Tensor]:
        """Global rest-pose positions ``(J, 3)`` of the joints and ``(E, 3)`` of the end sites.

        The rest pose is every rotation identity and every translation its offset, with the
        root's offset taken as the root's position.
        """
        pos = torch.zeros(self.num_joints, 3, dtype=torch.float64)
        for j, p in enumerate(self.parents):
            pos[j] = self.offsets[j] + (pos[p] if p >= 0 else 0.0)
        ends = (
            self.end_site_offsets + pos[list(self.end_site_parents)]
            if self.end_site_parents
            else torch.zeros(0, 3, dtype=torch.float64)
        )
        return pos, ends

    @property
    def is_depth_first(self) -> bool:
        """Whether every joint's subtree occupies the indices right after it (BVH's nesting order)."""
        count, last = [1] * self.num_joints, list(range(self.num_joints))
        for j in range(self.num_joints - 1, 0, -1):
            p = self.parents[j]
            count[p] += count[j]
            last[p] = max(last[p], last[j])
        return all(last[j] - j + 1 == count[j] for j in range(self.num_joints))

    def depth_first_order(self) -> list[int]:
        """The joints in BVH's nesting order: each joint followed by its subtree, children in
        index order (``list(range(J))`` when :attr:`is_depth_first`)."""
        kids: list[list[int]] = [[] for _ in range(self.num_joints)]
        for j, p in enumerate(self.parents):
            if p >= 0:
                kids[p].append(j)
        order, todo = [], [0]
        while todo:  # iterative: a chain of thousands of joints must not hit the recursion limit
            j = todo.pop()
            order.append(j)
            todo.extend(reversed(kids[j]))
        return order

    def reordered(self, order: list[int]) -> "Skeleton":
        """This skeleton with its joints in ``order`` (a permutation keeping joint 0 first and
        every parent before its children): new joint ``i`` is old joint ``order[i]``."""
        new = {old: i for i, old in enumerate(order)}
        return Skeleton(
            tuple(self.names[j] for j in order),
            tuple(-1 if self.parents[j] < 0 else new[self.parents[j]] for j in order),
            self.offsets[list(order)],
            tuple(self.channels[j] for j in order),
            tuple(new[p] for p in self.end_site_parents),
            self.end_site_offsets,
        )

    @functools.cached_property
    def _size(self) -> float:
        return self._compute_size()

    def size(self) -> float:
        """A length scale: the longest path between two leaves along the bones (file units).

        Leaves are end sites and childless joints; a path through the hierarchy sums bone
        lengths (offset norms), so for a human it is about the height or the arm span,
        whatever the rest pose and wherever the root's offset puts the skeleton (the offset
        of an animated joint right under the root is a trajectory, not a bone, and is not
        counted). Used for scale-relative tolerances.
        """
        return self._size

    def _compute_size(self) -> float:
        J = self.num_joints
        length = self.offsets.norm(dim=1).tolist()
        animated = self.translation_animated
        for c in self.children(0):
            if animated[c]:  # e.g. Bandai Namco's Hips under joint_Root: a trajectory, not a bone
                length[c] = 0.0
        down = [0.0] * J  # longest path from joint j down to a leaf below it
        best = 0.0
        tips: list[list[float]] = [[] for _ in range(J)]
        for e, p in enumerate(self.end_site_parents):
            tips[p].append(float(self.end_site_offsets[e].norm()))
        kids: list[list[int]] = [[] for _ in range(J)]
        for c, p in enumerate(self.parents):
            if p >= 0:
                kids[p].append(c)
        for j in range(J - 1, -1, -1):
            branches = sorted(tips[j] + [down[c] + length[c] for c in kids[j]], reverse=True)
            down[j] = branches[0] if branches else 0.0
            best = max(best, sum(branches[:2]))
        return best

    # -- comparison and serialisation ------------------------------------------------------
    def same_topology(self, other: "Skeleton") -> bool:
        """Same joint names in the same order with the same parents."""
        return self.names == other.names and self.parents == other.parents

    def _static_offset_error(self, other: "Skeleton") -> torch.Tensor:
        """Per joint ``(J,)``: offset difference, zero where the translation is animated.

        An animated translation replaces the offset frame by frame, so its offset does not
        matter (Bandai Namco's Hips offset differs between capture sessions).
        """
        d = (self.offsets - other.offsets).abs().max(dim=1).values
        animated = torch.tensor(self.translation_animated) | torch.tensor(other.translation_animated)
        return torch.where(animated, torch.zeros_like(d), d)

    def _end_site_error(self, other: "Skeleton") -> torch.Tensor:
        """Per End Site ``(E,)``: offset difference (the End Sites hang from the same joints)."""
        return (self.end_site_offsets - other.end_site_offsets).abs().max(dim=1).values

    def matches(self, other: "Skeleton", rtol: float = 1e-4) -> bool:
        """Same topology and channel layout, static offsets and End Sites equal within ``rtol`` of
        the size: End Sites are part of a clip (its leaf tails: head, hands, toes), so two
        skeletons whose End Sites differ are two skeletons."""
        if other is self:
            return True
        if not self.same_topology(other) or self.channels != other.channels:
            return False
        if self.end_site_parents != other.end_site_parents:
            return False
        if not self._same_scale(other):
            return False
        tol = rtol * max(self.size(), 1e-9)
        if self.end_site_parents and bool(self._end_site_error(other).max() > tol):
            return False
        return bool(self._static_offset_error(other).max() <= tol)

    def _same_scale(self, other: "Skeleton") -> bool:
        """Whether the two :meth:`size` agree within :data:`SCALE_RTOL`: the rest offsets of
        animated joints count here, so that a skeleton in metres never matches one in
        centimetres even when every joint is animated (Bandai Namco), where the offsets
        themselves are not compared."""
        a, b = self.size(), other.size()
        return abs(a - b) <= SCALE_RTOL * max(a, b, 1e-9)

    def mismatch(self, other: "Skeleton") -> str | None:
        """A short description of how ``other`` differs, or ``None`` when they match."""
        if self.names != other.names:
            missing = [n for n in self.names if n not in other.names]
            extra = [n for n in other.names if n not in self.names]
            if missing or extra:
                return f"joints differ (missing {missing[:5]}, extra {extra[:5]})"
            return "joints are in a different order"
        if self.parents != other.parents:
            j = next(i for i, (a, b) in enumerate(zip(self.parents, other.parents)) if a != b)
            return f"joint {self.names[j]!r} has a different parent"
        if self.channels != other.channels:
            j = next(i for i, (a, b) in enumerate(zip(self.channels, other.channels)) if a != b)
            return f"joint {self.names[j]!r} has different channels"
        if not self.matches(other):
            if not self._same_scale(other):
                return (
                    f"sizes differ ({self.size():.4g} against {other.size():.4g} file units: other units, or another "
                    "body)"
                )
            d = self._static_offset_error(other)
            j = int(d.argmax())
            if float(d[j]) > 1e-4 * max(self.size(), 1e-9):
                return f"bone offsets differ (joint {self.names[j]!r} by {float(d[j]):.4g})"
            if self.end_site_parents != other.end_site_parents:
                mine, theirs = len(self.end_site_parents), len(other.end_site_parents)
                if mine != theirs:
                    return f"End Sites differ ({mine} against {theirs})"
                e = next(i for i, (a, b) in enumerate(zip(self.end_site_parents, other.end_site_parents)) if a != b)
                return (
                    f"End Sites differ (End Site {e} hangs from joint {self.names[self.end_site_parents[e]]!r} "
                    f"against {other.names[other.end_site_parents[e]]!r})"
                )
            d = self._end_site_error(other)
            e = int(d.argmax())
            return f"End Site offsets differ (the End Site of joint {self.names[self.end_site_parents[e]]!r} by {float(d[e]):.4g})"
        return None

    def __repr__(self) -> str:
        return f"Skeleton({self.num_joints} joints, root {self.names[0]!r}, {len(self.end_site_parents)} end sites)"


def channel_columns(channels: list[list[str]]) -> tuple[list[dict[str, int]], int]:
    """The column of every (joint, channel) pair of BVH-style per-joint ``channels``, and the
    number of columns."""
    cols, c = [], 0
    for ch in channels:
        cols.append({name: c + k for k, name in enumerate(ch)})
        c += len(ch)
    return cols, c
