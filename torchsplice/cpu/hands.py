"""Compiled correction that keeps hands out of the body (:mod:`torchsplice.ops.hands`), clips packed along frames.

The same passes as :func:`torchsplice.ops.hands.keep_hands_out`, one clip per thread: per frame,
FK (:func:`.fk.fk_clip`) of the joints needed: ``arm``, the chain from the root to the wrists
(ascending, closed under parents), on every frame, and the ``rest`` (ascending, their parents in
either) on the frames a pass tests; then
``iterations`` passes of the push out of every obstacle (closed-form closest points of the
forearm's axis and each obstacle's; its normal kept on one side over a run of frames that
leaves the obstacle where it went in, and turned round the obstacle's side over a run that goes
through), taken into the chest's frame, spread in time (the largest
push within ``spread`` frames, then a Hann window of half-width ``spread``) and added to the
wrists' displacement, and two-bone IK of shoulder and elbow onto it, about each elbow's hinge (the
clip's mean plane normal in the upper arm's frame; none, and the chest's, where its mean is
``hinge_min`` or shorter), its reach's change damped by ``flex`` as there. The first pass tests
every frame, or, where ``frame_deepest`` ``(N,)`` is given (not empty: each frame's deepest probe
in an obstacle from :func:`.body.inside_clips`, exact wherever deeper than ``exact_above``) and a
clip's target is at least that, only the frames deeper than the target: the others cannot be
pushed. Later passes test the frames moved. The output is the same either way.

Shapes: rotations ``(N, J, 4)`` (unit WXYZ, local; ``out`` the same, written only at the moved
joints of changed frames, and may be ``rot`` itself: a clip's rows are all read before any is
written), translations ``(N, J, 3)`` (row 0 the root's position); capsule ends ``end_a``,
``end_b``, ``end_w`` ``(2C,)`` as :mod:`.body`'s; per arm (left, right) the joints
``shoulder``, ``elbow``, ``wrist`` and the parents ``shoulder_parent``, ``elbow_parent``
``(2,)``; per clip ``target`` (how deep a forearm may stay, the skeleton's units) and
``spread`` (frames); ``corrected`` ``(B,)`` the frames changed; ``changed`` ``(N,)`` uint8 (or
empty: not wanted), per frame a bit per moved joint whose value the correction changed (bit 0
left shoulder, 1 left elbow, 2 right shoulder, 3 right elbow: :attr:`~torchsplice.ops.hands.Arms.moved`'s
order), or-ed in; a joint the correction writes with its own value (NaN counting as equal to
NaN) keeps its bits.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from .fk import fk_clip
from .quat import qconj, qload, qmul, qrot
from .vec import add as _add, cross as _cross, dot as _dot, length as _length, normalized as _normalized
from .vec import row as _vec, scale as _scale, segment_closest as _closest, sub as _sub

__all__ = ["hands_out_clips"]


@njit(cache=True, inline="always")
def _between(u, v):
    """:func:`torchsplice.core.rotations.quat_between` of unit ``u``, ``v``."""
    d = _dot(u, v)
    if 1.0 + d < 1e-6:
        k = 0
        if abs(u[1]) < abs(u[k]):
            k = 1
        if abs(u[2]) < abs(u[k]):
            k = 2
        basis = (1.0 if k == 0 else 0.0, 1.0 if k == 1 else 0.0, 1.0 if k == 2 else 0.0)
        p = _cross(u, basis)
        q = (0.0, p[0], p[1], p[2])
    else:
        c = _cross(u, v)
        q = (1.0 + d, c[0], c[1], c[2])
    n = max(math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]), 1e-12)
    return (q[0] / n, q[1] / n, q[2] / n, q[3] / n)


@njit(cache=True, inline="always")
def _axis_angle(v):
    angle = _length(v)
    half = 0.5 * angle
    s = math.sin(half) / angle if angle > 1e-8 else 0.5 - angle * angle / 48.0
    return (math.cos(half), v[0] * s, v[1] * s, v[2] * s)


@njit(cache=True, nogil=True)
def _chest_hinge(upper, chest):
    """:func:`torchsplice.ops.hands.chest_hinge`: the chest's X axis less its part along the upper
    arm (its Z axis where the arm lies along X)."""
    unit = _scale(upper, 1.0 / max(_length(upper), 1e-300))
    side = qrot(chest, (1.0, 0.0, 0.0))
    side = _sub(side, _scale(unit, _dot(side, unit)))
    if _length(side) > 1e-6:
        return side
    side = qrot(chest, (0.0, 0.0, 1.0))
    return _sub(side, _scale(unit, _dot(side, unit)))


@njit(cache=True, nogil=True)
def _arm_ik(shoulder, elbow, wrist, target, hinge, flex):
    """:func:`torchsplice.ops.hands.arm_ik` of one arm, its joints' positions ``shoulder``, ``elbow``,
    ``wrist`` moved so that the wrist reaches ``target``: ``(elbow_turn, shoulder_turn, elbow', wrist')``,
    the elbow's and the shoulder's world rotations and the elbow's and wrist's new positions."""
    upper, lower = _sub(elbow, shoulder), _sub(wrist, elbow)
    upper_len = _length(upper)
    upper_dir = _scale(upper, 1.0 / max(upper_len, 1e-300))
    axis = _sub(hinge, _scale(upper_dir, _dot(hinge, upper_dir)))
    axis = _scale(axis, 1.0 / max(_length(axis), 1e-300))
    flat = _sub(lower, _scale(axis, _dot(lower, axis)))
    flat_len, lower_len = _length(flat), _length(lower)
    now = math.atan2(-_dot(_cross(upper_dir, flat), axis), _dot(flat, upper_dir))
    span = _length(_sub(wrist, shoulder))
    top = math.sqrt(upper_len * upper_len + lower_len * lower_len + 2.0 * upper_len * flat_len)
    bottom = math.sqrt(max(upper_len * upper_len + lower_len * lower_len - 2.0 * upper_len * flat_len, 0.0))
    change = (_length(_sub(target, shoulder)) - span) * (1.0 - math.exp(-(now / flex) ** 2))
    room = max(top - span if change > 0.0 else span - bottom, 1e-12 * (upper_len + lower_len))
    sign = 1.0 if change > 0.0 else -1.0 if change < 0.0 else 0.0
    reach = span + sign * room * -math.expm1(-abs(change) / room)
    want = math.acos(min(max((reach * reach - upper_len * upper_len - lower_len * lower_len)
                             / max(2.0 * upper_len * flat_len, 1e-300), -1.0), 1.0))
    if now < 0.0:
        want = -want
    elbow_turn = _axis_angle(_scale(axis, now - want))
    bent_wrist = _add(elbow, qrot(elbow_turn, lower))
    shoulder_turn = _between(_normalized(_sub(bent_wrist, shoulder), upper), _normalized(_sub(target, shoulder), upper))
    return (elbow_turn, shoulder_turn, _add(shoulder, qrot(shoulder_turn, upper)),
            _add(shoulder, qrot(shoulder_turn, _sub(bent_wrist, shoulder))))


@njit(cache=True, nogil=True)
def _contacts(pos, t, elbows, wrists, k, ends, end_a, end_b, end_w, radii, probe, obstacles, target, elbow, wrist,
              inside, away, apart, lever):
    """Arm ``k``'s forearm against every obstacle at frame ``t`` (see :mod:`torchsplice.ops.hands`'s
    ``_push``): per obstacle ``o`` (its place in ``obstacles``) into ``inside[t, k, o]`` whether the
    axis is deeper than ``target``, and there the way out ``away[t, k, o]`` (the normal at the
    closest point, world), the axes' distance ``apart[t, k, o]`` and the wrist's ``lever``; whether
    any is inside. ``elbows``, ``wrists (n, 2, 3)``: both arms' current positions, used for its
    ``elbow`` and ``wrist`` joints wherever a capsule end names them."""
    probe_ends = np.empty((2, 3))
    for e in range(2):
        row = 2 * probe + e
        for x in range(3):
            joint_a, joint_b = end_a[row], end_b[row]
            at_a = elbows[t, k, x] if joint_a == elbow else wrists[t, k, x] if joint_a == wrist else pos[t, joint_a, x]
            at_b = elbows[t, k, x] if joint_b == elbow else wrists[t, k, x] if joint_b == wrist else pos[t, joint_b, x]
            probe_ends[e, x] = at_a * (1.0 - end_w[row]) + at_b * end_w[row] if end_w[row] != 0.0 else at_a
    probe_a, probe_b = _vec(probe_ends, 0), _vec(probe_ends, 1)
    arm = _length(_sub((wrists[t, k, 0], wrists[t, k, 1], wrists[t, k, 2]),
                       (elbows[t, k, 0], elbows[t, k, 1], elbows[t, k, 2])))
    probe_mid, probe_half = _scale(_add(probe_a, probe_b), 0.5), 0.5 * _length(_sub(probe_b, probe_a))
    hit = False
    for i in range(obstacles.shape[0]):
        o = obstacles[i]
        inside[t, k, i] = False
        obstacle_a, obstacle_b = _vec(ends[t], 2 * o), _vec(ends[t], 2 * o + 1)
        # the midpoints' distance less both half-lengths bounds the axes' distance from below: an
        # obstacle surely out of reach is skipped (the margin keeps rounding from skipping one that is not)
        mid_apart = _length(_sub(probe_mid, _scale(_add(obstacle_a, obstacle_b), 0.5)))
        reach = probe_half + 0.5 * _length(_sub(obstacle_b, obstacle_a))
        if mid_apart - reach > radii[o] - target + 1e-9 * (mid_apart + reach + radii[o]):
            continue
        s, u = _closest(probe_a, probe_b, obstacle_a, obstacle_b)
        on_probe = _add(probe_a, _scale(_sub(probe_b, probe_a), s))
        on_obstacle = _add(obstacle_a, _scale(_sub(obstacle_b, obstacle_a), u))
        distance = _length(_sub(on_probe, on_obstacle))
        if radii[o] - distance - target > 0.0:
            inside[t, k, i] = True
            hit = True
            way = _normalized(_sub(on_probe, on_obstacle), _sub(on_probe, _scale(_add(obstacle_a, obstacle_b), 0.5)))
            away[t, k, i, 0], away[t, k, i, 1], away[t, k, i, 2] = way
            apart[t, k, i] = distance
            lever[t, k, i] = min(max(_length(_sub(probe_b, probe_a)) / max(arm, 1e-300) * s, 0.5), 2.0)
    return hit


@njit(cache=True, nogil=True)
def _pushes(pushed, n_pushed, inside, away, apart, lever, radii, obstacles, round_, target, slack, pos, grot, chest,
            ends, runs, sides, pushes):
    """The wrists' moves out of the obstacles (chest frame) into ``pushes[t]`` for the frames
    ``pushed[:n_pushed]`` (ascending) of a pass, from :func:`_contacts`: per obstacle its way out
    times how far beyond ``target`` the forearm goes, plus ``slack``, over the lever, summed.
    Over a run of consecutive frames inside one obstacle (:func:`torchsplice.ops.hands._runs`)
    the normal's turns are counted. Where the run began and ends on one side and the normal has
    turned over since it began, the way out is reversed, ``apart`` further (``_turned_back``);
    where the run went through an obstacle of ``round_`` ``(O,)`` (:data:`torchsplice.ops.hands.ROUND`),
    the way is round its side away from the chest (``_way_round``), out to the same depth.
    ``pos (n, J, 3)``: the frames' joint positions (the chest's read); ``ends (n, 2C, 3)``: their
    capsule ends; scratch ``runs (n, 2, O, 3)`` (the turns so far in a frame's run, in its whole
    run, and the run's first frame) and ``sides (n, 2, O, 2)`` (the obstacle's middle from the
    chest along the run's side, summed over the run, and the sizes of those). Where the pushes of
    a frame sum to zero it is dropped from ``pushed``; the new count is returned."""
    n_obstacles = obstacles.shape[0]
    for i in range(n_pushed):  # the normal's reversals counted along each run, its offsets summed ...
        t = pushed[i]
        for k in range(2):
            for o in range(n_obstacles):
                if not inside[t, k, o]:
                    continue
                runs[t, k, o, 0], runs[t, k, o, 2] = 0, t
                sides[t, k, o, 0] = sides[t, k, o, 1] = 0.0
                if i > 0 and pushed[i - 1] == t - 1 and inside[t - 1, k, o]:
                    turned = (away[t, k, o, 0] * away[t - 1, k, o, 0] + away[t, k, o, 1] * away[t - 1, k, o, 1]
                              + away[t, k, o, 2] * away[t - 1, k, o, 2]) < 0.0
                    runs[t, k, o, 0] = runs[t - 1, k, o, 0] + (1 if turned else 0)
                    runs[t, k, o, 2] = runs[t - 1, k, o, 2]
                    sides[t, k, o, 0], sides[t, k, o, 1] = sides[t - 1, k, o, 0], sides[t - 1, k, o, 1]
                middle = _scale(_add(_vec(ends[t], 2 * obstacles[o]), _vec(ends[t], 2 * obstacles[o] + 1)), 0.5)
                along = _dot(_sub(middle, _vec(pos[t], chest)), _across(ends, t, obstacles[o], away, runs[t, k, o, 2], k, o))
                sides[t, k, o, 0] += along
                sides[t, k, o, 1] += abs(along)
    for i in range(n_pushed - 1, -1, -1):  # ... and each run's totals, from its end back
        t = pushed[i]
        for k in range(2):
            for o in range(n_obstacles):
                if not inside[t, k, o]:
                    continue
                if i + 1 < n_pushed and pushed[i + 1] == t + 1 and inside[t + 1, k, o]:
                    runs[t, k, o, 1] = runs[t + 1, k, o, 1]
                    sides[t, k, o, 0], sides[t, k, o, 1] = sides[t + 1, k, o, 0], sides[t + 1, k, o, 1]
                else:
                    runs[t, k, o, 1] = runs[t, k, o, 0]
    kept = 0
    for i in range(n_pushed):
        t = pushed[i]
        to_chest = qconj(qload(grot, t, chest))
        hit = False
        for k in range(2):
            push = (0.0, 0.0, 0.0)
            for o in range(n_obstacles):
                if not inside[t, k, o]:
                    continue
                way = (away[t, k, o, 0], away[t, k, o, 1], away[t, k, o, 2])
                radius = radii[obstacles[o]]
                if runs[t, k, o, 1] % 2 == 1 and round_[o]:  # went through the torso: round its side
                    across = _across(ends, t, obstacles[o], away, runs[t, k, o, 2], k, o)
                    side = _scale(across, -1.0 if sides[t, k, o, 0] < -1e-9 * sides[t, k, o, 1] else 1.0)
                    offset = _scale(way, apart[t, k, o])
                    way_round = _normalized(_add(offset, _scale(side, max(radius - apart[t, k, o], 0.0))), way)
                    move = _sub(_scale(way_round, radius - target + slack), offset)
                    push = _add(push, _scale(move, 1.0 / lever[t, k, o]))
                    continue
                excess = radius - apart[t, k, o] - target
                if runs[t, k, o, 0] % 2 == 1 and runs[t, k, o, 1] % 2 == 0:  # turned back: out through the entry side
                    way = _scale(way, -1.0)
                    excess = radius + apart[t, k, o] - target
                push = _add(push, _scale(way, (excess + slack) / lever[t, k, o]))
            if push[0] != 0.0 or push[1] != 0.0 or push[2] != 0.0:
                hit = True
                push = qrot(to_chest, push)
            pushes[t, k, 0], pushes[t, k, 1], pushes[t, k, 2] = push
        if hit:
            pushed[kept] = t
            kept += 1
    return kept


@njit(cache=True, inline="always")
def _across(ends, t, obstacle, away, entry, k, o):
    """The side of a run through ``obstacle`` at frame ``t``: its axis crossed with the run's
    entry normal (``away`` at frame ``entry``), unit (zero where they are parallel)."""
    axis = _sub(_vec(ends[t], 2 * obstacle + 1), _vec(ends[t], 2 * obstacle))
    return _normalized(_cross(axis, _vec(away[entry, k], o)), (0.0, 0.0, 0.0))


@njit(cache=True, nogil=True)
def _body_frame(rot, trans, parents, rest, end_a, end_b, end_w, row, t, pos, grot, ends, whole):
    """The FK of the ``rest`` of frame ``t``'s joints (packed row ``row``) and its capsule ends,
    once (``whole[t]`` says it is done)."""
    if whole[t]:
        return
    fk_clip(rot[row:row + 1], trans[row:row + 1], parents, rest, 1, pos[t:t + 1], grot[t:t + 1])
    for e in range(end_a.shape[0]):
        for x in range(3):
            ends[t, e, x] = pos[t, end_a[e], x] * (1.0 - end_w[e]) + pos[t, end_b[e], x] * end_w[e]
    whole[t] = True


@njit(cache=True, inline="always")
def _write_joint(out, row, joint, q):
    """``out[row, joint] = q`` where that changes its value (in ``out``'s dtype; NaN counts as
    equal to NaN), ``1``; else ``out`` keeps its bits (a zero's sign included), ``0``."""
    old = (out[row, joint, 0], out[row, joint, 1], out[row, joint, 2], out[row, joint, 3])
    differs = False
    for x in range(4):
        out[row, joint, x] = q[x]
        new = out[row, joint, x]
        if new != old[x] and not (math.isnan(new) and math.isnan(old[x])):
            differs = True
    if differs:
        return 1
    for x in range(4):
        out[row, joint, x] = old[x]
    return 0


@njit(cache=True, parallel=True)
def hands_out_clips(rot, trans, parents, arm, rest, end_a, end_b, end_w, radii, probes, obstacles, round_, chest,
                    shoulder, elbow, wrist, shoulder_parent, elbow_parent, starts, lengths, target, spread, slack, iterations,
                    hinge_min, flex, frame_deepest, exact_above, out, corrected, changed):
    """Per clip ``c`` (rows ``starts[c]:starts[c]+lengths[c]``) into ``out`` and ``corrected[c]``
    (see the module docstring)."""
    J = rot.shape[1]
    n_ends = end_a.shape[0]
    for c in prange(starts.shape[0]):
        n, first, half = lengths[c], starts[c], spread[c]
        pos = np.zeros((n, J, 3))
        grot = np.zeros((n, J, 4))
        ends = np.empty((n, n_ends, 3))
        whole = np.zeros(n, np.bool_)  # the frame's FK done beyond the arms, and its capsule ends
        elbows = np.empty((n, 2, 3))
        wrists = np.empty((n, 2, 3))
        shift = np.zeros((n, 2, 3))  # the wrists' displacement, chest frame
        pushes = np.zeros((n, 2, 3))
        widest = np.zeros((n, 2, 3))
        turns = np.zeros((n, 2, 8))  # per arm: the elbow's turn, the shoulder's
        pushed = np.empty(n, np.int64)
        n_obstacles = obstacles.shape[0]
        inside = np.zeros((n, 2, n_obstacles), np.bool_)  # per frame, arm and obstacle: the forearm in it (_contacts)
        away = np.empty((n, 2, n_obstacles, 3))
        apart = np.empty((n, 2, n_obstacles))
        lever = np.empty((n, 2, n_obstacles))
        runs = np.empty((n, 2, n_obstacles, 3), np.int64)
        sides = np.empty((n, 2, n_obstacles, 2))
        # the frames the first pass must test: all, or those the body test measured deeper than the
        # target (exact there when the target is at least exact_above; the margin covers rounding)
        known = frame_deepest.shape[0] > 0 and target[c] * (1.0 - 1e-6) >= exact_above
        fk_clip(rot[first:first + n], trans[first:first + n], parents, arm, n, pos, grot)
        for t in range(n):
            for k in range(2):
                for x in range(3):
                    elbows[t, k, x] = pos[t, elbow[k], x]
                    wrists[t, k, x] = pos[t, wrist[k], x]
        hinges = np.zeros((2, 3))  # the clip's elbow hinges, in the upper arms' frames (ops.hands.elbow_hinges)
        for k in range(2):
            for t in range(n):
                upper_arm = _sub(_vec(elbows[t], k), _vec(pos[t], shoulder[k]))
                forearm = _sub(_vec(wrists[t], k), _vec(elbows[t], k))
                normal = _scale(_cross(_scale(upper_arm, -1.0), forearm),
                                1.0 / max(_length(upper_arm) * _length(forearm), 1e-300))
                local_normal = qrot(qconj(qload(grot, t, shoulder[k])), normal)
                for x in range(3):
                    hinges[k, x] += local_normal[x]
            for x in range(3):
                hinges[k, x] /= max(n, 1)
            if _length(_vec(hinges, k)) <= hinge_min:
                hinges[k, 0] = hinges[k, 1] = hinges[k, 2] = 0.0
        moved = np.zeros(n, np.bool_)
        hann = np.empty(2 * half + 1)  # the spread's weights by offset d = -spread..spread
        for d in range(2 * half + 1):
            hann[d] = 1.0 + math.cos(math.pi * (d - half) / (half + 1.0))
        for it in range(iterations):
            n_pushed = 0  # the frames pushed in this pass, ascending: pushed[:n_pushed]
            for t in range(n):
                if it > 0 and not moved[t]:
                    continue  # a frame no pass has moved was out already, and is still
                if it == 0 and known and not frame_deepest[first + t] > target[c] * (1.0 - 1e-6):
                    continue  # no obstacle as deep as the target
                _body_frame(rot, trans, parents, rest, end_a, end_b, end_w, first + t, t, pos, grot, ends, whole)
                hit = False
                for k in range(2):
                    if _contacts(pos, t, elbows, wrists, k, ends, end_a, end_b, end_w, radii, probes[k], obstacles,
                                 target[c], elbow[k], wrist[k], inside, away, apart, lever):
                        hit = True
                if hit:
                    pushed[n_pushed] = t
                    n_pushed += 1
            n_pushed = _pushes(pushed, n_pushed, inside, away, apart, lever, radii, obstacles, round_, target[c], slack,
                               pos, grot, chest, ends, runs, sides, pushes)
            if n_pushed == 0:
                break
            # a push reaches `spread` frames by the largest-push step and as many more by the window:
            # only the frames within 2 spread of a pushed frame change (elsewhere `pushes` and `widest`
            # are zero, and the window would add zeros)
            done = -1
            for i in range(n_pushed):  # the spread in time: the largest push within spread ...
                for t in range(max(pushed[i] - half, done + 1, 0), min(pushed[i] + half, n - 1) + 1):
                    for k in range(2):
                        best, size = t, -1.0
                        for g in range(max(t - half, 0), min(t + half, n - 1) + 1):
                            s2 = (pushes[g, k, 0] * pushes[g, k, 0] + pushes[g, k, 1] * pushes[g, k, 1]
                                  + pushes[g, k, 2] * pushes[g, k, 2])
                            if s2 > size:
                                best, size = g, s2
                        for x in range(3):
                            widest[t, k, x] = pushes[best, k, x]
                    done = t
            done = -1
            for i in range(n_pushed):  # ... then a Hann window of half-width spread, and the IK where it changed
                for t in range(max(pushed[i] - 2 * half, done + 1, 0), min(pushed[i] + 2 * half, n - 1) + 1):
                    done = t
                    den = 0.0
                    for f in range(max(t - half, 0), min(t + half, n - 1) + 1):
                        den += hann[f - t + half]
                    chest_rot = qload(grot, t, chest)
                    for k in range(2):
                        num0 = num1 = num2 = 0.0
                        for f in range(max(t - half, 0), min(t + half, n - 1) + 1):
                            weight = hann[f - t + half]
                            num0 += weight * widest[f, k, 0]
                            num1 += weight * widest[f, k, 1]
                            num2 += weight * widest[f, k, 2]
                        shift[t, k, 0] += num0 / den
                        shift[t, k, 1] += num1 / den
                        shift[t, k, 2] += num2 / den
                        if num0 == 0.0 and num1 == 0.0 and num2 == 0.0:
                            continue  # unchanged since its last IK (an addition of zero)
                        if shift[t, k, 0] == 0.0 and shift[t, k, 1] == 0.0 and shift[t, k, 2] == 0.0:
                            continue  # nothing to move
                        moved[t] = True
                        d = qrot(chest_rot, (shift[t, k, 0], shift[t, k, 1], shift[t, k, 2]))
                        shoulder_pos = _vec(pos[t], shoulder[k])
                        wrist_pos = _vec(pos[t], wrist[k])
                        elbow_pos = _vec(pos[t], elbow[k])
                        hinge_local = _vec(hinges, k)
                        if hinge_local[0] != 0.0 or hinge_local[1] != 0.0 or hinge_local[2] != 0.0:
                            hinge = qrot(qload(grot, t, shoulder[k]), hinge_local)
                        else:
                            hinge = _chest_hinge(_sub(elbow_pos, shoulder_pos), chest_rot)
                        elbow_turn, shoulder_turn, new_elbow, new_wrist = _arm_ik(shoulder_pos, elbow_pos, wrist_pos,
                                                                                  _add(wrist_pos, d), hinge, flex)
                        for x in range(4):
                            turns[t, k, x], turns[t, k, 4 + x] = elbow_turn[x], shoulder_turn[x]
                        for x in range(3):
                            elbows[t, k, x], wrists[t, k, x] = new_elbow[x], new_wrist[x]
            for i in range(n_pushed):  # zeros again for the next pass
                for t in range(max(pushed[i] - half, 0), min(pushed[i] + half, n - 1) + 1):
                    for k in range(2):
                        for x in range(3):
                            widest[t, k, x] = 0.0
                for k in range(2):
                    for x in range(3):
                        pushes[pushed[i], k, x] = 0.0
        count = 0
        for t in range(n):
            if not moved[t]:
                continue
            count += 1
            for k in range(2):
                if shift[t, k, 0] == 0.0 and shift[t, k, 1] == 0.0 and shift[t, k, 2] == 0.0:
                    continue
                elbow_turn = (turns[t, k, 0], turns[t, k, 1], turns[t, k, 2], turns[t, k, 3])
                shoulder_turn = (turns[t, k, 4], turns[t, k, 5], turns[t, k, 6], turns[t, k, 7])
                shoulder_local = qmul(qconj(qload(grot, t, shoulder_parent[k])),
                                      qmul(shoulder_turn, qload(grot, t, shoulder[k])))
                elbow_local = qmul(qconj(qload(grot, t, elbow_parent[k])), qmul(elbow_turn, qload(grot, t, elbow[k])))
                bits = _write_joint(out, first + t, shoulder[k], shoulder_local) << (2 * k)
                bits |= _write_joint(out, first + t, elbow[k], elbow_local) << (2 * k + 1)
                if changed.shape[0] > 0:
                    changed[first + t] |= bits
        corrected[c] = count
