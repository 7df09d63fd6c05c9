"""Keep hands out of the body: move an arm whose hand or forearm enters the body, by the least change.

A spliced clip's arms come from the action, its torso from the splice's pelvis and posture
correction and its legs from the locomotion, so a hand the action kept clear of its own body
can end up inside the result's torso or thigh (an idle arm swinging into a turned torso). This
moves it out:

1. The body's capsules (:mod:`.body`) give, per frame and arm, how deep the forearm's axis
   (with the hand) enters each obstacle beyond what the clip may keep (``allowed``, its sources'
   own deepest, and at least half :data:`~.body.INSIDE_MARGIN`), and the way out: the capsule's
   normal at the closest point, kept on one side over frames where the forearm crosses the
   obstacle's axis and comes back out where it went in (``_turned_back``), and turned round the
   obstacle's side over frames where it goes through (``_way_round``).
2. That push, as a move of the wrist, is taken into the chest's frame, spread in time (each
   frame takes the largest push within :data:`RAMP` seconds, then a Hann window of that
   half-width smooths it; no pop where the correction starts or ends) and added to the wrist's
   displacement so far.
3. Two-bone IK on the shoulder and elbow puts the wrist at its place in the chest's frame plus
   that displacement: the elbow bends about its hinge to the new reach, then the shoulder
   swings the arm by the shortest arc. The hinge is the clip's own, fixed in the upper arm
   (:func:`elbow_hinges`), so the elbow moves smoothly through frames where the arm is
   straight. The hand keeps its rotation relative to the forearm.

Steps 1 to 3 run up to :data:`ITERATIONS` times (until no push is left), each solving the IK
from the clip's own arms with the displacement summed so far; frames with no displacement keep
their rotations bit for bit,
and nothing but the shoulders' and elbows' rotations changes (the root, the legs and the feet
are untouched). An idle arm keeps its swing where it stays clear of the body.

Conventions: clips packed along frames, local rotations ``(N, J, 4)`` unit WXYZ and local
translations ``(N, J, 3)`` (row 0 the root's position), ``lengths (B,)``, ``fps (B,)``;
``allowed (B,)`` in the skeleton's units. Work is in float64, the result in the input's dtype.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from ..core.fk import forward_kinematics
from ..core.rotations import axis_angle_to_quat, quat_apply, quat_between, quat_conj, quat_mul
from ..core.skeleton import Skeleton
from ..specs.canonical import canonical_joints
from ..specs.roles import SkeletonRoles
from .body import Body, capsule_ends, segment_closest

__all__ = ["RAMP", "ITERATIONS", "CLEARANCE", "SLACK", "FLEX", "HINGE_MIN", "ROUND", "Arms", "arms_of", "keep_hands_out",
           "spread_in_time", "arm_ik", "elbow_hinges", "hinge_axes", "chest_hinge"]

RAMP = 0.15
"""Seconds over which a correction ramps in and out (the half-width of its spread in time)."""
ITERATIONS = 24
"""Passes of push, spread and IK (each from the clip's own arms)."""
CLEARANCE = 0.5
"""How deep a forearm may stay in an obstacle, at least, as a share of the body's margin (a
frame counts as inside beyond the margin): the correction acts beyond half the margin."""
SLACK = 0.25
"""How far short of that depth (or of the clip's ``allowed``) a push aims, as a share of the
margin, so that a few passes reach it rather than creep towards it."""
FLEX = 0.5
"""Radians of elbow flexion (0 straight) below which the IK changes an arm's reach less and
swings it more (see :func:`arm_ik`)."""
ROUND = ("torso_l", "torso_r")
"""The obstacles (:data:`~.body.OBSTACLES`) a forearm that goes through is taken round (``_way_round``):
the torso's two capsules, whose outside is away from the chest. Through the others (the thighs and
shins, which swing and turn under the arm; the pelvis and head, whose outside no side of the body
names) it is pushed along the normal, as a run that does not cross the axis is."""
HINGE_MIN = 1e-3
"""A clip's mean elbow-plane normal (:func:`elbow_hinges`) shorter than this gives no hinge: its
arm is straight (bent less than about 0.06 degrees) on average."""


@dataclass(frozen=True)
class Arms:
    """The joints the correction reads and moves (indices into the skeleton): ``chest`` (the
    joint the arms hang from), and per side ``(left, right)`` the ``shoulder``, ``elbow`` and
    ``wrist``; ``probes`` the body's forearm capsules of each side."""

    chest: int
    shoulder: tuple[int, int]
    elbow: tuple[int, int]
    wrist: tuple[int, int]
    probes: tuple[int, int]

    @property
    def moved(self) -> tuple[int, int, int, int]:
        """The joints whose rotations change: left shoulder, left elbow, right shoulder, right elbow."""
        return self.shoulder[0], self.elbow[0], self.shoulder[1], self.elbow[1]


def arms_of(skeleton: Skeleton, roles: SkeletonRoles, body: Body, what: str = "the skeleton") -> Arms:
    """The :class:`Arms` of ``skeleton`` (bound ``roles``; ``body`` its :func:`~.body.body_of`)."""
    j = canonical_joints(roles, skeleton, what)
    chest = skeleton.parents[j["clavicle_l"] if "clavicle_l" in j else j["shoulder_l"]]
    return Arms(chest, (j["shoulder_l"], j["shoulder_r"]), (j["elbow_l"], j["elbow_r"]), (j["wrist_l"], j["wrist_r"]),
                (body.names.index("forearm_l"), body.names.index("forearm_r")))


def _frames(lengths: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Per packed frame: its clip, its clip's first frame and one past its last."""
    clip = torch.repeat_interleave(torch.arange(len(lengths)), lengths)
    end = torch.cumsum(lengths, 0)
    return clip, (end - lengths)[clip], end[clip]


def spread_in_time(push: torch.Tensor, lengths: torch.Tensor, fps: torch.Tensor, ramp: float = RAMP) -> torch.Tensor:
    """``push`` ``(N, A, 3)`` (clips packed along frames) spread in time within each clip: every
    frame takes the largest vector (by length, per ``A``) within ``w = round(ramp fps)`` frames
    of it, then a Hann window of half-width ``w`` (weights ``1 + cos(pi d / (w + 1))``, renormalised at a clip's
    ends) averages those. Zero far from any push; a lone push becomes a ramp ``2 w`` frames wide
    each side, reaching its full size where pushes are ``w`` frames deep or more."""
    N = push.shape[0]
    if N == 0:
        return push.clone()
    clip, first, end = _frames(lengths)
    fps = torch.as_tensor(fps, dtype=torch.float64).expand(len(lengths))
    w = torch.round(ramp * fps).long().clamp_min(1)[clip]  # (N,)
    W = int(w.max())
    d = torch.arange(-W, W + 1)
    at = torch.arange(N)[:, None] + d[None, :]
    inside = (at >= first[:, None]) & (at < end[:, None]) & (d.abs()[None, :] <= w[:, None])  # (N, 2W + 1)
    at = torch.where(inside, at, torch.arange(N)[:, None])
    size = torch.where(inside[..., None], (push * push).sum(-1)[at], -1.0)  # (N, 2W + 1, A)
    best = at.gather(1, size.argmax(1))  # (N, A): the frame of the largest push near each
    widest = push[best, torch.arange(push.shape[1])[None, :]]  # (N, A, 3)
    weight = torch.where(inside, 1.0 + torch.cos(torch.pi * d[None, :] / (w[:, None] + 1.0)), 0.0).to(push.dtype)
    return (widest[at] * weight[..., None, None]).sum(1) / weight.sum(1)[:, None, None]


def _normalized(v: torch.Tensor, fallback: torch.Tensor) -> torch.Tensor:
    n = _length(v)[..., None]
    f = fallback / _length(fallback)[..., None].clamp_min(1e-300)
    return torch.where(n > 1e-12, v / n.clamp_min(1e-300), f)


def chest_hinge(upper: torch.Tensor, chest_rot: torch.Tensor) -> torch.Tensor:
    """An elbow's hinge where the clip gives none (its arm straight on every frame): the chest's
    X axis, less its part along the upper arm (the chest's Z axis where the arm lies along X)."""
    unit = upper / _length(upper)[..., None].clamp_min(1e-300)
    out = None
    for axis in ((1.0, 0.0, 0.0), (0.0, 0.0, 1.0)):
        side = quat_apply(chest_rot, torch.tensor(axis, dtype=upper.dtype).expand_as(upper))
        side = side - (side * unit).sum(-1, keepdim=True) * unit
        out = side if out is None else torch.where((_length(out) > 1e-6)[..., None], out, side)
    return out


def elbow_hinges(upper: torch.Tensor, lower: torch.Tensor, upper_rot: torch.Tensor, lengths: torch.Tensor) -> torch.Tensor:
    """``(B, 2, 3)`` each clip's elbow hinge per arm, in its upper arm's frame: the mean over
    the clip's frames of the arm's plane normal ``(-upper x lower) / (l1 l2)`` (a bent frame
    weighs by the sine of its bend, a straight one nothing), taken into the frame of the upper
    arm's joint (``upper_rot`` ``(N, 2, 4)``, its global rotation); zero where the arm is
    straight on every frame. ``upper``, ``lower`` ``(N, 2, 3)``, clips packed along frames.

    A human elbow is a hinge fixed in the upper arm, so this axis is the same on every frame of
    a clip; the IK bends about it (turned with the upper arm) instead of about each frame's own
    plane, which has no direction where the arm is straight and would flip the elbow there."""
    normal = torch.linalg.cross(-upper, lower, dim=-1) / (_length(upper) * _length(lower)).clamp_min(1e-300)[..., None]
    local = quat_apply(quat_conj(upper_rot), normal)
    clip = torch.repeat_interleave(torch.arange(len(lengths)), lengths)
    total = torch.zeros(len(lengths), *upper.shape[1:], dtype=upper.dtype).index_add(0, clip, local)
    mean = total / lengths.clamp_min(1)[:, None, None].to(upper.dtype)
    return torch.where((_length(mean) > HINGE_MIN)[..., None], mean, 0.0)


def hinge_axes(hinges: torch.Tensor, upper_rot: torch.Tensor, upper: torch.Tensor, chest_rot: torch.Tensor) -> torch.Tensor:
    """``(..., 3)`` the elbow's hinge in the world per frame: a clip's :func:`elbow_hinges` row
    ``hinges`` turned by the upper arm's rotation ``upper_rot`` ``(..., 4)``, or
    :func:`chest_hinge` where the clip has none."""
    turned = quat_apply(upper_rot, hinges)
    return torch.where((_length(hinges) > 0)[..., None], turned, chest_hinge(upper, chest_rot))


def arm_ik(S: torch.Tensor, E: torch.Tensor, W: torch.Tensor, T: torch.Tensor,
           hinge: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """Two-bone IK: ``(q1, q2, E', W')`` for shoulder, elbow and wrist at ``S``, ``E``, ``W`` and
    the wrist's target ``T`` (``(..., 3)``): the elbow's turn about its hinge (``hinge``
    ``(..., 3)``, less its part along the upper arm; it points along ``-upper x lower`` of the
    arm bent) to a new reach, then the whole arm's shortest turn about the shoulder onto the
    target's direction, and where they put the elbow and wrist. The bones keep their lengths.

    The forearm's flexion is its angle about the hinge from the upper arm's line: positive bent,
    zero straight, below zero overstretched, so it runs smoothly through a straight arm, which
    has no plane of its own; the new flexion keeps its side.
    The reach changes by the target's, ``d - d0``, times ``1 - exp(-(flexion / FLEX)^2)`` (all
    of it for an arm bent more than about 2 ``FLEX``, nothing for a straight one, which swings
    instead: bending a straight arm moves the elbow as the square root of the change, a jolt),
    and saturates smoothly short of the reach the bones allow (``h (1 - exp(-e / h))`` for an
    extension ``e`` with headroom ``h``, likewise for a fold), so the elbow never snaps straight.
    A target the arm already reaches gives back the arm; one moved across the shoulder's
    sphere (at the arm's own reach) is met. (Unlike the legs' :func:`~.feet.two_bone_ik`, which
    keeps a knee no straighter than it is, an arm may straighten: pushing a forearm out of the
    body often needs that.)"""
    upper, lower = E - S, W - E
    l1 = _length(upper)
    u = upper / l1.clamp_min(1e-300)[..., None]
    a = hinge - (hinge * u).sum(-1, keepdim=True) * u
    a = a / _length(a).clamp_min(1e-300)[..., None]
    flat = lower - (lower * a).sum(-1, keepdim=True) * a  # the forearm in the hinge's plane
    lf, l2 = _length(flat), _length(lower)
    now = torch.atan2(-(torch.linalg.cross(u, flat, dim=-1) * a).sum(-1), (flat * u).sum(-1))
    d0 = _length(W - S)
    # what the forearm's turn about the hinge can reach: from folded to straight
    top = (l1 ** 2 + l2 ** 2 + 2 * l1 * lf).sqrt()
    bottom = (l1 ** 2 + l2 ** 2 - 2 * l1 * lf).clamp_min(0.0).sqrt()
    e = (_length(T - S) - d0) * (1.0 - torch.exp(-(now / FLEX) ** 2))
    room = torch.where(e > 0, top - d0, d0 - bottom).clamp_min(1e-12 * (l1 + l2))
    reach = d0 + torch.sign(e) * room * -torch.expm1(-e.abs() / room)
    want = torch.acos(((reach ** 2 - l1 ** 2 - l2 ** 2) / (2 * l1 * lf).clamp_min(1e-300)).clamp(-1.0, 1.0))
    want = torch.where(now < 0, -want, want)  # an overstretched arm stays on its side: no kink through straight
    q1 = axis_angle_to_quat(a * (now - want)[..., None])
    W1 = E + quat_apply(q1, lower)
    q2 = quat_between(_normalized(W1 - S, upper), _normalized(T - S, upper))
    return q1, q2, S + quat_apply(q2, upper), S + quat_apply(q2, W1 - S)


def _length(v: torch.Tensor) -> torch.Tensor:
    return (v * v).sum(-1).sqrt()  # faster than torch's norm on rows of three


def _probe_ends(pos: torch.Tensor, E: torch.Tensor, W: torch.Tensor, body: Body, arms: Arms) -> tuple:
    """Both ends ``(n, 2, 1, 3)`` of each arm's probe capsule with its elbow and wrist at ``E``,
    ``W`` ``(n, 2, 3)`` (the other joints at ``pos``)."""
    ends = []
    for e in (0, 1):
        side = []
        for k, probe in enumerate(arms.probes):
            a, b = body.end_joints[2 * probe + e].tolist()
            point = lambda j: E[:, k] if j == arms.elbow[k] else W[:, k] if j == arms.wrist[k] else pos[:, j]  # noqa: E731
            share = float(body.end_shares[2 * probe + e])
            side.append(point(a) + share * (point(b) - point(a)) if share else point(a))
        ends.append(torch.stack(side, 1)[:, :, None])
    return ends[0], ends[1]


def _push(pos, E, W, oa, ob, radii, round_, target, slack: float, body: Body, arms: Arms,
          follows: torch.Tensor) -> torch.Tensor:
    """``(n, 2, 3)`` per frame and arm, the move of the wrist (world) that takes the forearm's
    axis, where it is deeper than ``target`` ``(n,)`` in an obstacle, out to ``slack`` less
    deep than that, with the elbow and wrist at ``E``, ``W`` ``(n, 2, 3)``; zero where it is
    out already. ``follows`` ``(n,)``: the row is its clip's frame after the previous row's;
    ``round_`` ``(O,)``: the obstacles of :data:`ROUND`.

    The way out is the capsule's normal at the closest point, except over a run of frames in
    which the forearm crosses the obstacle's axis (:func:`_runs`): a forearm that crosses and
    comes back is pushed out of the side it entered all along (:func:`_turned_back`), and one
    that goes through the torso is taken round it (:func:`_way_round`). Pushed along the bare
    normal, either would swing through the body where the normal turns over."""
    pa, pb = _probe_ends(pos, E, W, body, arms)
    s, t = segment_closest(pa, pb, oa, ob)
    cp, co = pa + (pb - pa) * s[..., None], oa + (ob - oa) * t[..., None]
    apart = _length(cp - co)
    excess = radii - apart - target[:, None, None]  # (n, 2, O)
    inside = excess > 0
    if not bool(inside.any()):
        return torch.zeros_like(E)
    away = _normalized(cp - co, cp - (oa + ob) / 2)
    runs = _runs(away, inside, follows)
    back = _turned_back(away, inside, follows, runs)
    away = torch.where(back[..., None], -away, away)
    excess = torch.where(back, radii + apart - target[:, None, None], excess)  # out through the entry side
    excess = torch.where(inside, excess + slack, 0.0)  # beyond the target: out to slack below it
    lever = (_length(pb - pa) / _length(W - E).clamp_min(1e-300)[..., None] * s).clamp(0.5, 2.0)
    move = away * (excess / lever)[..., None]
    through = inside & (runs[2] % 2 == 1) & round_
    if bool(through.any()):  # round the obstacle: out to the same depth along the way round
        way = _way_round(away, apart, oa, ob, radii, pos[:, arms.chest, None, None], runs)
        reach = radii - target[:, None, None] + slack
        move = torch.where(through[..., None], (way * reach[..., None] - away * apart[..., None]) / lever[..., None],
                           move)
    return move.sum(2)


def _runs(away: torch.Tensor, inside: torch.Tensor, follows: torch.Tensor) -> tuple:
    """The runs of :func:`_push`'s frames: a run is the consecutive frames (``follows`` ``(n,)``)
    on which an arm is ``inside`` ``(n, 2, O)`` one obstacle, and a step of it turns the way out
    ``away`` ``(n, 2, O, 3)`` (the normal at the closest point) over where consecutive normals
    have a negative dot product: the forearm's axis crossed the obstacle's. Per frame, arm and
    obstacle ``(n, 2, O)``: ``(start, turns so far, turns in the whole run)``, ``start`` the
    run's first row."""
    n = len(away)
    link = torch.zeros_like(inside)
    link[1:] = follows[1:, None, None] & inside[1:] & inside[:-1]
    reversed_ = torch.zeros_like(inside)
    reversed_[1:] = link[1:] & ((away[1:] * away[:-1]).sum(-1) < 0)
    count = torch.cumsum(reversed_.long(), 0)
    row = torch.arange(n)[:, None, None].expand_as(inside)
    start = torch.cummax(torch.where(link, -1, row), 0).values
    ends = torch.zeros_like(inside)  # the next row does not continue the run
    ends[:-1] = ~link[1:]
    ends[-1] = True
    end = torch.flip(torch.cummin(torch.flip(torch.where(ends, row, n), [0]), 0).values, [0])
    first = count.gather(0, start)
    return start, count - first, count.gather(0, end) - first


def _turned_back(away: torch.Tensor, inside: torch.Tensor, follows: torch.Tensor, runs: tuple | None = None) -> torch.Tensor:
    """``(n, 2, O)``: where the way out ``away`` is reversed (see :func:`_runs` for the shapes).
    Where a run turns over an even number of times, it left the obstacle on the side it entered,
    so its frames after an odd number of turns are reversed: pushed out on that side all along.
    A run that turns an odd number of times went through the obstacle (:func:`_way_round`)."""
    _, so_far, total = _runs(away, inside, follows) if runs is None else runs
    return inside & (so_far % 2 == 1) & (total % 2 == 0)


def _way_round(away: torch.Tensor, apart: torch.Tensor, oa: torch.Tensor, ob: torch.Tensor, radii: torch.Tensor,
               centre: torch.Tensor, runs: tuple) -> torch.Tensor:
    """``(n, 2, O, 3)``: the way out of a run that goes through its obstacle (an odd number of
    turns, :func:`_runs`), round the obstacle's side rather than through its axis. The side is
    across the axis (``oa`` to ``ob``, ``(n, 1, O, 3)``) from the run's entry normal (``away`` at
    its first frame), on the obstacle's side away from the body's ``centre`` (the chest,
    ``(n, 1, 1, 3)``; summed over the run, ``+`` on a tie within rounding): round the torso's
    outside (:data:`ROUND`), never into the rest of the body. The way is the offset
    ``away * apart`` plus the side times what the offset lacks of the radius (``radii - apart``,
    at least 0), made unit: the entry normal where the forearm enters, the side where it crosses
    the axis, the exit normal where it leaves. Where the entry normal lies along the axis there
    is no side: the normal."""
    start = runs[0]
    entry = away.gather(0, start[..., None].expand_as(away))
    across = _normalized(torch.linalg.cross((ob - oa).expand_as(away), entry, dim=-1), torch.zeros_like(away))
    along = (((oa + ob) / 2 - centre) * across).sum(-1)
    total = torch.zeros_like(along).scatter_add_(0, start, along).gather(0, start)  # each run's sum
    size = torch.zeros_like(along).scatter_add_(0, start, along.abs()).gather(0, start)
    side = torch.where(total < -1e-9 * size, -1.0, 1.0)[..., None] * across
    offset = away * apart[..., None]
    return _normalized(offset + side * (radii - apart).clamp_min(0.0)[..., None], away)


def _near(flag: torch.Tensor, radius: torch.Tensor, first: torch.Tensor, end: torch.Tensor) -> torch.Tensor:
    """``(N,)`` the packed frames within ``radius`` ``(N,)`` frames of a flagged one of their clip."""
    i = torch.arange(len(flag))
    before = torch.cummax(torch.where(flag, i, -1), 0).values
    after = torch.flip(torch.cummin(torch.flip(torch.where(flag, i, len(flag)), [0]), 0).values, [0])
    return ((before >= first) & (i - before <= radius)) | ((after < end) & (after - i <= radius))


def keep_hands_out(rotations: torch.Tensor, translations: torch.Tensor, lengths, fps, skeleton: Skeleton, body: Body,
                   arms: Arms, allowed) -> tuple[torch.Tensor, torch.Tensor]:
    """``(rotations, corrected)``: the clips' rotations ``(N, J, 4)`` with each arm moved out of
    the body where its forearm enters an obstacle deeper than the clip's ``allowed`` (see the
    module docstring), and per clip ``(B,)`` how many frames changed. The passes run on the
    frames near a hand inside only (those a correction can reach), with the same result."""
    lengths = torch.as_tensor(lengths, dtype=torch.long)
    B = len(lengths)
    fps = torch.as_tensor(fps, dtype=torch.float64).expand(B)
    allowed = torch.as_tensor(allowed, dtype=torch.float64).expand(B)
    out = rotations.clone()
    none = torch.zeros(B, dtype=torch.long)
    if rotations.shape[0] == 0:
        return out, none
    rot = rotations.to(torch.float64)
    trans = translations.to(torch.float64)
    pos, grot = forward_kinematics(rot, trans[:, 0], skeleton.offsets.to(torch.float64), skeleton.parents, trans)
    clip, first, end = _frames(lengths)
    sh, el, wr = list(arms.shoulder), list(arms.elbow), list(arms.wrist)
    hinges = elbow_hinges(pos[:, el] - pos[:, sh], pos[:, wr] - pos[:, el], grot[:, sh], lengths)  # (B, 2, 3)
    target = torch.maximum(allowed, torch.tensor(CLEARANCE * body.margin, dtype=torch.float64))[clip]  # (N,)
    a, b = capsule_ends(pos, body)
    obstacles = list(body.obstacles)
    radii = body.radii.to(torch.float64)[obstacles]
    round_ = torch.tensor([body.names[o] in ROUND for o in obstacles])
    slack = SLACK * body.margin
    push = _push(pos, pos[:, el], pos[:, wr], a[:, None, obstacles], b[:, None, obstacles], radii, round_, target, slack,
                 body, arms, torch.arange(len(pos)) > first)
    inside = (push != 0).any(-1).any(-1)
    if not bool(inside.any()):
        return out, none
    # the frames a correction can reach: each pass spreads a push 2 w frames, and reads w beyond
    w = torch.round(RAMP * fps).long().clamp_min(1)[clip]
    keep = torch.nonzero(_near(inside, (2 * ITERATIONS + 1) * w + 1, first, end)).flatten()
    f, c = keep, clip[keep]
    run = torch.ones(len(f), dtype=torch.bool)
    run[1:] = (f[1:] != f[:-1] + 1) | (c[1:] != c[:-1])
    seg = torch.cumsum(run.long(), 0) - 1
    seg_lengths = torch.bincount(seg)
    seg_clip = c[run]
    pos, grot, target = pos[f], grot[f], target[f]
    n = len(f)
    S, E0, W0 = pos[:, sh], pos[:, el], pos[:, wr]  # (n, 2, 3)
    chest = grot[:, arms.chest, None].expand(n, 2, 4)
    hinge = hinge_axes(hinges[c], grot[:, sh], E0 - S, chest)  # (n, 2, 3)
    oa, ob = a[f][:, None, obstacles], b[f][:, None, obstacles]  # (n, 1, O, 3): they do not move with the arms
    D = torch.zeros(n, 2, 3, dtype=torch.float64)  # the wrists' displacement, chest's frame
    E, W = E0.clone(), W0.clone()
    q1 = torch.zeros(n, 2, 4, dtype=torch.float64)
    q1[..., 0] = 1.0
    q2 = q1.clone()
    for k in range(ITERATIONS):
        if k == 0:
            p = push[f]
        else:  # a frame no pass has moved was out already, and is still
            m = torch.nonzero((D != 0).any(-1).any(-1)).flatten()
            p = torch.zeros_like(D)
            follows = ~run[m]  # the row after its clip's previous frame
            follows[1:] &= m[1:] == m[:-1] + 1
            p[m] = _push(pos[m], E[m], W[m], oa[m], ob[m], radii, round_, target[m], slack, body, arms, follows)
        if not bool((p != 0).any()):
            break
        D = D + spread_in_time(quat_apply(quat_conj(chest), p), seg_lengths, fps[seg_clip])
        r, k = torch.nonzero((D != 0).any(-1), as_tuple=True)  # each arm that has moved
        q1[r, k], q2[r, k], E[r, k], W[r, k] = arm_ik(S[r, k], E0[r, k], W0[r, k], W0[r, k] + quat_apply(chest[r, k], D[r, k]),
                                                      hinge[r, k])
    changed = (D != 0).any(-1)  # (n, 2)
    parents = skeleton.parents
    for k, (s_, e_) in enumerate(zip(arms.shoulder, arms.elbow)):
        new_s = quat_mul(quat_conj(grot[:, parents[s_]]), quat_mul(q2[:, k], grot[:, s_]))
        new_e = quat_mul(quat_conj(grot[:, parents[e_]]), quat_mul(q1[:, k], grot[:, e_]))
        m = changed[:, k, None]
        out[f, s_] = torch.where(m, new_s.to(out.dtype), out[f, s_])
        out[f, e_] = torch.where(m, new_e.to(out.dtype), out[f, e_])
    return out, none.index_add(0, c, changed.any(-1).long())
