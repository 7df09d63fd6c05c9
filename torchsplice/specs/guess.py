"""Guessing the joint roles of a skeleton no dataset spec fits (what the ``generic`` spec
does), from common joint names, the hierarchy and the rest pose: :func:`guess_joints` gives
the joint fields of the guessed spec; :meth:`DatasetSpec.guess_for
<torchsplice.specs.DatasetSpec.guess_for>` makes the spec and :func:`~torchsplice.specs.guess_spec`
describes the guess.
"""

from __future__ import annotations

import math
import re

from ..core.errors import SpecError
from ..core.skeleton import POSITION_CHANNELS, Skeleton

from .roles import chain, is_ancestor
from .vocabulary import AXES

__all__ = ["guess_joints", "cannot_guess"]


# --------------------------------------------------------------------------------------------
# guessing
# --------------------------------------------------------------------------------------------
_KNEE = {"knee", "leg", "lowerleg", "lowleg", "loleg", "calf", "shin"}
_THIGH = {"upleg", "upperleg", "uleg", "thigh", "hip"}
_FOOT = {"foot", "ankle"}
_TOE = {"toe", "toes", "toebase", "ball", "foottoe"}
_ELBOW = {"elbow", "forearm", "lowerarm", "lowarm", "loarm"}
_UPPERARM = {"upperarm", "uparm", "arm", "humerus"}
_HAND = {"hand", "wrist"}
_HEAD = {"head"}
_PARTS = _KNEE | _THIGH | _FOOT | _TOE | _ELBOW | _UPPERARM | _HAND | _HEAD | {"collar", "clavicle", "shoulder"}
_IGNORED = {"bip", "joint", "jnt", "def", "bone", "mixamorig", "j"}
_SIDES = {"l": "L", "left": "L", "lft": "L", "r": "R", "right": "R", "rgt": "R"}
_TWIST_WORDS = ("twist", "helper")
"""Words that make a joint a twist/helper bone wherever they stand in its name (``ForeTwist``);
``roll`` counts as a word of its own or at the end (``LeftArmRoll``, ``upperarm_roll_l``,
``l_forearmroll``)."""
_TWIST_MAX_BEND = 25.0
"""Degrees: a numbered continuation (``upperleg01.L > upperleg02.L``) bending more than this
away from its parent's direction in the rest pose starts a new segment, not a twist bone."""
_LEGS_HANG = 0.5
"""The rest pose shows the legs hanging down when each foot is below its hip by at least this
fraction of the leg's length along the bones; else the quadruped check cannot tell."""
_REACH = 0.25
"""A front limb reaches the ground when its lowest point is within this fraction of the hip
height (above the feet) of the feet's level."""
_UPRIGHT = 60.0
"""Degrees: a spine (pelvis to chest) further than this from the up axis is horizontal."""


def _name_words(name: str) -> list[str]:
    """Lower-case words of a joint name, namespace (``mixamorig:``) dropped, digits kept."""
    name = re.split(r"[:|]", name)[-1]
    return [t.lower() for t in re.findall(r"[A-Z]+(?![a-z])|[A-Z]?[a-z]+|\d+", name)]


def _numbered_base(name: str) -> str:
    """A joint name without its numbers: ``upperleg02.L`` -> ``upperleg.l``,
    ``DEF-thigh.L.001`` -> ``def-thigh.l``."""
    return re.sub(r"[\s._-]*\d+", "", name).strip(" ._-").lower()


def _side_and_core(name: str) -> tuple[str | None, str]:
    """``("L" | "R" | None, core)`` of a joint name, e.g. ``"LeftUpLeg"`` -> ``("L", "upleg")``.

    Namespaces (``mixamorig:``) and digits are dropped; sides are read from ``Left``/``L``/``l_``
    /``_L`` tokens, or a glued ``l``/``r`` prefix before a body-part word (``lhand``).
    """
    tokens = [t for t in _name_words(name) if not t.isdigit() and t not in _IGNORED]
    sides = {_SIDES[t] for t in tokens if t in _SIDES}
    core = "".join(t for t in tokens if t not in _SIDES)
    if len(sides) == 1:
        return sides.pop(), core
    for word, side in (("left", "L"), ("right", "R")):
        if core.startswith(word) and len(core) > len(word):
            return side, core[len(word) :]
    if len(core) > 1 and core[0] in "lr" and core[1:] in _PARTS:
        return core[0].upper(), core[1:]
    return None, core


class _Guesser:
    """Finds limbs on one skeleton by name, then derives their neighbours from the hierarchy,
    passing over twist/roll/helper bones (see :meth:`is_twist`)."""

    def __init__(self, sk: Skeleton):
        self.sk = sk
        self.parsed = [_side_and_core(n) for n in sk.names]
        self.words = [_name_words(n) for n in sk.names]
        self.rest = sk.rest_positions()[0]
        self.notes: list[str] = []

    def fail(self, problem: str, joints: bool = True) -> SpecError:
        """A SpecError saying what could not be guessed, listing the joints unless told not to."""
        return cannot_guess(self.sk, problem, joints)

    def named(self, side: str | None, parts: set[str]) -> list[int]:
        """Joints whose side is ``side`` and whose core is one of ``parts``, in index order."""
        return [j for j, (s, c) in enumerate(self.parsed) if s == side and c in parts]

    def only_child(self, j: int) -> int | None:
        """``j``'s child if it has exactly one."""
        kids = self.sk.children(j)
        return kids[0] if len(kids) == 1 else None

    def is_twist(self, j: int, toward: int | None = None) -> bool:
        """Whether ``j`` is a twist, roll or helper bone inside a limb segment rather than the
        joint that starts the next segment: named so (``twist``, ``roll``, ``helper``:
        ``upperarm_twist_01_l``, ``LeftArmRoll``, ``Bip01 L ForeTwist``), or a numbered
        continuation of its parent (``upperleg01.L > upperleg02.L``, ``DEF-thigh.L >
        DEF-thigh.L.001``) that carries on in its parent's direction toward ``toward`` (the
        joint the limb continues to) in the rest pose, within :data:`_TWIST_MAX_BEND` degrees;
        where the rest pose cannot tell (no ``toward``, a zero-length bone), the name decides."""
        core, words = self.parsed[j][1], self.words[j]
        if any(w in core for w in _TWIST_WORDS) or "roll" in words or core.endswith("roll"):
            return True
        p = self.sk.parents[j]
        name = self.sk.names[j]
        if p < 0 or not re.search(r"\d", name) or _numbered_base(name) != _numbered_base(self.sk.names[p]):
            return False
        if toward is None:
            return True
        a, b = self.rest[j] - self.rest[p], self.rest[toward] - self.rest[j]
        na, nb = float(a.norm()), float(b.norm())
        if na <= 1e-9 or nb <= 1e-9:
            return True
        return float(a @ b) / (na * nb) >= math.cos(math.radians(_TWIST_MAX_BEND))

    def segment_top(self, j: int) -> int:
        """The joint that starts the segment ``j`` hangs from: ``j``'s parent, or above the
        twist bones in line between them (``lowerleg01.L`` -> ``upperleg01.L``, not
        ``upperleg02.L``); ``-1`` above the root."""
        below, p = j, self.sk.parents[j]
        while p >= 0 and self.sk.parents[p] >= 0 and self.is_twist(p, below):
            below, p = p, self.sk.parents[p]
        return p

    def next_segment(self, j: int, parts: set[str]) -> int | None:
        """The child of ``j`` that starts the next segment: the one named like ``parts``; else,
        when ``j``'s only children with descendants are twist bones in line (``lowerleg01.L >
        lowerleg02.L > foot.L``, ``LeftForeArm > LeftForeArmRoll > LeftHand``), the next
        segment below that one; else the only child that is not a twist bone; else ``None``."""
        kids = self.sk.children(j)
        named = [c for c in kids if self.parsed[c][1] in parts]
        if named:
            return named[0]
        plain = [c for c in kids if not self.is_twist(c, self.only_child(c))]
        inline = [c for c in kids if c not in plain and self.sk.children(c)]
        if not plain and len(inline) == 1:
            return self.next_segment(inline[0], parts)
        return plain[0] if len(plain) == 1 else None

    def middle(self, side: str, mid: set[str], upper: set[str], lower: set[str], what: str) -> int:
        """The knee or elbow of one side: by its own name, else below an upper / above a lower
        joint (twist bones never count)."""
        named = [j for j in self.named(side, mid) if self.sk.children(j) and self.sk.parents[j] >= 0]
        plain = [j for j in named if not self.is_twist(j, self.only_child(j))]
        if plain or named:
            return (plain or named)[0]
        depth = lambda j: len(self._path_up(j))  # noqa: E731
        uppers = [j for j in self.named(side, upper) if not self.is_twist(j, self.only_child(j))]
        for j in sorted(uppers, key=depth, reverse=True):
            c = self.next_segment(j, set())
            if c is not None and self.sk.children(c):
                self.notes.append(f"{what} {self.sk.names[c]}: the child of {self.sk.names[j]}")
                return c
        for j in sorted(self.named(side, lower), key=depth):
            p = self.segment_top(j)
            if p >= 0 and self.sk.parents[p] >= 0:
                self.notes.append(f"{what} {self.sk.names[p]}: the parent of {self.sk.names[j]}")
                return p
        side_word = "left" if side == "L" else "right"
        raise self.fail(f"no {side_word} {what} found (looked for joint names like {', '.join(sorted(mid))})")

    def limb(
        self, mid: set[str], upper: set[str], lower: set[str], end: set[str], what: str, end_required: bool = True
    ):
        """``(upper, middle, lower)`` index pairs (left, right) of the legs or arms; ``lower``
        is ``None`` when it cannot be told and is not required."""
        mids = tuple(self.middle(s, mid, upper, lower, what) for s in ("L", "R"))
        tops = tuple(self.segment_top(m) for m in mids)
        ends = tuple(self.next_segment(m, end) for m in mids)
        if None in ends and not end_required:
            self.notes.append(f"no {'/'.join(sorted(end))} joints found below the {what}s")
            return tops, mids, None
        if None in ends:
            m = mids[ends.index(None)]
            raise self.fail(f"cannot tell which child of the {what} {self.sk.names[m]!r} continues the limb")
        return tops, mids, ends

    def _path_up(self, j: int) -> list[int]:
        """``j`` and its ancestors, bottom-up."""
        path = []
        while j >= 0:
            path.append(j)
            j = self.sk.parents[j]
        return path

    def common_ancestor(self, joints) -> int:
        """The lowest joint that is an ancestor-or-self of every joint in ``joints``."""
        paths = [self._path_up(j) for j in joints]
        shared = set(paths[0]).intersection(*paths[1:])
        return next(j for j in paths[0] if j in shared)

    def toward(self, top: int, j: int) -> int:
        """The child of ``top`` on the path down to ``j``."""
        path = self._path_up(j)
        return path[path.index(top) - 1]


def cannot_guess(skeleton: Skeleton, problem: str, joints: bool = True) -> SpecError:
    """The :class:`SpecError` saying that the joint roles of ``skeleton`` cannot be guessed and
    why (``problem``), listing its joints unless ``joints`` is false."""
    listed = f"; its joints: {', '.join(skeleton.names)}" if joints else ""
    return SpecError(
        f"cannot guess the joint roles of this skeleton: {problem}; write a dataset "
        f"spec (see datasets_spec/README.md){listed}"
    )


def guess_joints(skeleton: Skeleton, up_axis: str) -> dict:
    """The joint fields of a spec guessed for ``skeleton`` whose up axis is ``up_axis``: the
    keyword arguments ``root``, ``pelvis``, ``spine``, ``hips``, ``knees``, ``feet``,
    ``shoulders``, ``toes``, ``hands``, ``head``, ``notes`` and ``guessed`` of a
    :class:`~torchsplice.specs.DatasetSpec` (how: see :func:`~torchsplice.specs.guess_spec`).

    Raises :class:`SpecError` (:func:`cannot_guess`) saying what could not be found, or why the
    skeleton does not look like a humanoid.
    """
    g = _Guesser(skeleton)
    hips, knees, feet = g.limb(_KNEE, _THIGH, _FOOT, _FOOT, "knee")
    shoulders, elbows, hands = g.limb(_ELBOW, _UPPERARM, _HAND, _HAND, "elbow", end_required=False)
    toes = tuple(g.next_segment(f, _TOE) for f in feet)
    top = g.common_ancestor([*hips, *shoulders])
    if top in (*hips, *shoulders):
        raise g.fail(f"the legs and arms do not branch apart ({skeleton.names[top]!r} is a limb joint)")
    chest = g.common_ancestor(shoulders)
    if chest == top:
        raise g.fail(
            f"the arms branch from {skeleton.names[top]!r}, the same joint as the legs, so no joint can be the pelvis"
        )
    pelvis = g.toward(top, chest)
    root = _trajectory_joint(skeleton, top)
    heads = [j for j, (_, core) in enumerate(g.parsed) if core in _HEAD and is_ancestor(skeleton.parents, pelvis, j)]
    head = heads[0] if heads else None
    spine = chain(skeleton.parents, pelvis, skeleton.parents[head] if head is not None else chest)
    problem, posture = _posture(skeleton, AXES[up_axis], pelvis, chest, head, hips, feet, shoulders)
    if problem is not None:
        raise g.fail(problem, joints=False)
    n = skeleton.names
    pair = lambda p: (n[p[0]], n[p[1]])  # noqa: E731
    names = lambda js: tuple(n[j] for j in js)  # noqa: E731
    legs = [(hips[s], knees[s], feet[s]) + ((toes[s],) if None not in toes else ()) for s in (0, 1)]
    arms = [(shoulders[s], elbows[s]) + ((hands[s],) if hands else ()) for s in (0, 1)]
    skipped = [j for limb in legs + arms for a, b in zip(limb, limb[1:]) for j in chain(skeleton.parents, a, b)[1:-1]]
    guessed = (
        ("root", (n[root],)),
        ("pelvis", (n[pelvis],)),
        ("spine", names(spine)),
        ("head", (n[head],) if head is not None else ()),
        ("left_leg", names(legs[0])),
        ("right_leg", names(legs[1])),
        ("left_arm", names(arms[0])),
        ("right_arm", names(arms[1])),
        ("skipped", names(skipped)),
    )
    return dict(
        root=n[root],
        pelvis=n[pelvis],
        spine=tuple(n[j] for j in spine),
        hips=pair(hips),
        knees=pair(knees),
        feet=pair(feet),
        shoulders=pair(shoulders),
        toes=pair(toes) if None not in toes else None,
        hands=pair(hands) if hands else None,
        head=n[head] if head is not None else None,
        notes=tuple(
            _guess_notes(
                skeleton,
                g.notes,
                root,
                top,
                pelvis,
                head,
                toes,
                dict(
                    hips=hips, knees=knees, feet=feet, shoulders=shoulders, elbows=elbows, hands=hands or (None, None)
                ),
                skipped,
                posture,
            )
        ),
        guessed=guessed,
    )


def _trajectory_joint(sk: Skeleton, top: int) -> int:
    """``top`` if its position is animated, else its nearest ancestor that is, else joint 0."""
    j = top
    while j >= 0:
        if any(c in POSITION_CHANNELS for c in sk.channels[j]):
            return j
        j = sk.parents[j]
    return 0


def _guess_notes(sk, notes, root, top, pelvis, head, toes, limbs, skipped, posture) -> list[str]:
    """What :func:`guess_joints` guessed and how, one line each."""
    n = sk.names
    out = [
        "guessed from joint names and the hierarchy: "
        + "; ".join(f"{key} {n[a]}/{n[b]}" for key, (a, b) in limbs.items() if (a, b) != (None, None))
    ]
    out += notes
    out.append(
        "knees and elbows found by name unless said otherwise; hips and shoulders are the joints "
        "above them (shoulder = glenohumeral joint, not the clavicle), feet and hands the ones below, "
        "each the joint that starts the next segment"
    )
    if skipped:
        out.append(f"twist/roll/helper bones passed over (no role): {', '.join(n[j] for j in skipped)}")
    out.append(
        f"root {n[root]}: "
        + (
            "the joint where legs and arms branch"
            if root == top
            else f"nearest animated ancestor of {n[top]}, where legs and arms branch"
        )
    )
    out.append(f"pelvis {n[pelvis]}: the first joint from {n[top]} toward the shoulders")
    out.append(f"head {n[head]}" if head is not None else "no head joint found; the spine ends where the arms branch")
    if None in toes:
        out.append("no toe joints found")
    out.append(posture)
    out.append("units unknown; up axis assumed y")
    return out


def _posture(
    sk: Skeleton, up: int, pelvis: int, chest: int, head: int | None, hips, feet, shoulders
) -> tuple[str | None, str]:
    """Whether the rest pose is a humanoid's, standing upright: ``(problem, note)``, ``problem``
    ``None`` when it is (or when the rest pose cannot tell), else why not (see :func:`~torchsplice.specs.guess_spec`)."""
    axis = "xyz"[up]
    pos, ends = sk.rest_positions()
    height = pos[:, up]
    leg = [sum(float(sk.offsets[k].norm()) for k in chain(sk.parents, h, f)[1:]) for h, f in zip(hips, feet)]
    drop = [float(height[h] - height[f]) for h, f in zip(hips, feet)]
    if min(leg) <= 0 or any(d < _LEGS_HANG * length for d, length in zip(drop, leg)):
        return None, f"the rest pose does not show the legs hanging down along {axis}: quadruped check skipped"

    def lowest(j):
        inside = set(sk.descendants(j))
        tips = [float(ends[e, up]) for e, p in enumerate(sk.end_site_parents) if p in inside]
        return min([float(height[k]) for k in inside] + tips)

    ground = min(lowest(h) for h in hips)
    stand = min(float(height[h]) for h in hips) - ground
    gaps = [lowest(s) - ground for s in shoulders]
    four = all(gap <= _REACH * stand for gap in gaps)
    n = sk.names
    top = chest if chest != pelvis else head
    spine = None
    if top is not None and float((pos[top] - pos[pelvis]).norm()) > 0.05 * stand:
        v = pos[top] - pos[pelvis]
        tilt = math.degrees(math.acos(max(-1.0, min(1.0, float(v[up] / v.norm())))))
        spine = (tilt, f"the spine ({n[pelvis]} to {n[top]}) is {tilt:.0f} degrees off the up axis {axis}")
    level = spine is not None and spine[0] > _UPRIGHT
    if four or level:
        reasons = (
            [f"4 limbs reach the ground in the rest pose (the arms {n[shoulders[0]]}, {n[shoulders[1]]} too)"]
            if four
            else []
        )
        reasons += [spine[1]] if spine is not None and level else []
        what = "it looks like a quadruped" if four else "it does not stand upright like a humanoid"
        return f"{what}: {'; '.join(reasons)}", ""
    return None, (
        f"rest pose upright: {spine[1] if spine else 'legs hanging down'}; the arms end "
        f"{min(gaps) / stand:.0%} of the hip height above the feet"
    )
