"""Mirror images of clips on any skeleton with a left/right map: data augmentation, like
HumanML3D's ``M`` copies, for every rig.

Conventions (as everywhere: quaternions WXYZ, file units, the file's up axis):

- The mirror is the world reflection ``M`` that negates one horizontal axis, ``axis``: X for
  Y-up and Z-up data, Y for X-up data (:func:`mirror_axis`). For a character facing +Z (Y up)
  it swaps its left and right in place; a clip walking along +X comes back walking along -X.
- Joints pair by name (:func:`side_partners`): ``Left``/``Right``, ``left``/``right`` and
  ``LEFT``/``RIGHT`` as a word or a CamelCase part of the name (``LeftArm``, ``left_knee``,
  ``handLeft``, ``LEFT_ARM``; not ``Bright`` or ``leftover``), else ``L``/``R`` and ``l``/``r`` as
  a letter of their own (``l_hip``, ``RHand``, ``hand_r``, ``Bip01 L Thigh``), a side anywhere
  in the name (``Leftfoot``) or a leading lower-case letter (CMU's ``lhand``); these last three
  only where the partner exists (``ROOT`` is not the partner of a ``LOOT``). A joint with
  neither side is its own partner; a rig where no joint pairs is refused. End sites pair with their
  joints. The partners must form a mirror-symmetric hierarchy (a joint's partner's parent is
  its parent's partner).
- The mirrored clip keeps the skeleton: joint ``j`` moves as ``M`` applied to its partner,
  ``p'_j = M p_σ(j)``. Its world rotations are ``G'_k = M G_σ(k) M S_k``, where ``S_k`` is a
  constant rotation of joint ``k``'s frame taking its children's rest offsets to the mirror
  images of its partner's children's (``S_k o_c = M o_σ(c)``; Horn's least-squares rotation over
  the children and end sites, the smallest rotation for one child). For a rig whose rest pose
  is symmetric (``o_σ(c) = M o_c``: the sample, SMPL) ``S = I`` and this is the usual
  reflection of the rotations; for one whose rest is not (Bandai Namco's, every bone along its
  parent's +X) ``S`` conjugates it. The positions are exact where the rig's two sides are
  congruent (Bandai Namco and LAFAN1 to their files' rounding, under 0.001 cm); where they are
  not, the mirror keeps the rig's own bones and misses the reflection by their difference
  (CMU's sides differ by up to 0.66 of its units, about 4 cm, along a chain). Where one child's
  rest offset is opposite its target, the half turn is about the axis perpendicular to the bone
  nearest the up axis (a bone's twist is then a convention; positions are exact).
- Animated joint translations (Bandai Namco's ``Hips`` under ``joint_Root``) are the mirrored
  positions expressed in the mirrored parent's frame, so they are exact too.

- Local rotations come out canonical over time: the first frame's ``w >= 0`` and each later
  frame in the hemisphere of the one before (no sign flips between frames).

Labels and names are swapped by :func:`mirror_text` (left and right, clockwise and
counterclockwise, as words or parts of compound words: ``wave-right-hand`` becomes
``wave-left-hand``), except the labels that name clips or files (:data:`IDENTITY_LABELS`:
``split_from``, ``mirror_of``, ``retargeted_from`` ...; a spliced clip's ``locomotion`` and
``action``), so that a mirror image stays with its sources in splits. ``mirror_of`` names the
take the clip comes from: the clip itself, or for a window (``split_from``) its take, and it
is kept when a mirror image is mirrored again. Mirroring twice gives the clip's positions back
on a rig whose two sides are congruent.
"""

from __future__ import annotations

import re
from dataclasses import replace

import torch

from ..core.errors import TorchspliceError
from ..core.fk import forward_kinematics
from ..core.motion import Motion
from ..core.rotations import quat_conj, quat_mul, quat_to_rotmat, rotmat_to_quat
from ..core.skeleton import Skeleton

__all__ = ["mirror_axis", "side_partners", "mirror_rest", "mirror_rig", "mirror_motion", "mirror_text", "mirror_labels",
           "IDENTITY_LABELS"]

_SIDES = {"left": "right", "right": "left", "Left": "Right", "Right": "Left", "LEFT": "RIGHT", "RIGHT": "LEFT"}
_SIDE_PART = re.compile(r"(?<![A-Za-z])(?:left|right)(?![a-z])|(?:Left|Right)(?![a-z])|(?<![A-Z])(?:LEFT|RIGHT)")
"""A side in a joint's name: a word (``left_knee``), a CamelCase part (``LeftArm``, ``handLeft``)
or capitals (``LEFT_ARM``, ``LEFTARM``); not inside another word (``Bright``, ``leftover``)."""
_LETTER = re.compile(r"(?:(?<=^)|(?<=[_:.\s|-]))([LlRr])(?=[A-Z0-9_.:\s|-]|$)")
_SIDE_WORD = re.compile(r"(?<![A-Za-z])(?i:counterclockwise|anticlockwise|clockwise|left|right)(?![a-z])"
                        r"|(?<=[a-z])(?:Counterclockwise|Anticlockwise|Clockwise|Left|Right)(?![a-z])")
"""A side word: on its own or in a compound (``wave-left``, ``LEFT_ARM``), or a CamelCase part
(``handLeft``); not inside another word (``leftover``)."""
_WORDS = {"left": "right", "right": "left", "clockwise": "counterclockwise", "counterclockwise": "clockwise",
          "anticlockwise": "clockwise"}

IDENTITY_LABELS = frozenset({"mirror_of", "split_from", "split_frame", "split", "retargeted_from", "retargeted_to",
                             "path", "source", "file", "database", "id"})
"""Labels that name a clip, a file or a place rather than describe the motion: a mirror image
keeps them as they are (so do a spliced clip's ``action.`` and ``locomotion.`` copies of them,
and its ``locomotion`` and ``action``, the names of its source clips)."""


def mirror_axis(up_axis: int) -> int:
    """The world axis the mirror negates: X (0) unless X is up, then Y (1)."""
    return 1 if int(up_axis) == 0 else 0


_LOOSE = re.compile("left|right|Left|Right|LEFT|RIGHT")
"""A side anywhere in a name (``Leftfoot``, ``HANDLEFT``): trusted only where the partner exists."""
_LEADING = re.compile(r"^([lr])(?=[a-z])")
"""A leading lower-case side letter (CMU's ``lhand``, ASF's ``lhumerus``): trusted only where the
partner exists."""


def _partner_name(name: str, names) -> str:
    """The partner's name: the name itself for a joint of neither side. A side word is a word
    or CamelCase part (its partner must exist); a side letter, a side anywhere in the name or a
    leading lower-case letter pair only with a joint of ``names``."""
    swapped = _SIDE_PART.sub(lambda m: _SIDES[m.group(0)], name)
    if swapped != name:
        return swapped
    letters = {"L": "R", "R": "L", "l": "r", "r": "l"}
    for candidate in (_LETTER.sub(lambda m: letters[m.group(1)], name), _LOOSE.sub(lambda m: _SIDES[m.group(0)], name),
                      _LEADING.sub(lambda m: letters[m.group(1)], name)):
        if candidate != name and candidate in names:
            return candidate
    return name


def side_partners(skeleton: Skeleton, where: str = "") -> list[int]:
    """``sigma``: each joint's left/right partner (itself for a joint of neither side), by name.

    Raises a one-line :class:`~torchsplice.core.errors.TorchspliceError` naming ``where`` (a file
    or clip) and the joint when a side's joint has no partner, when no joint pairs at all (a rig
    of more than one joint whose sides its names do not say), or when the partners' hierarchy is
    not mirror-symmetric."""
    names = list(skeleton.names)
    index = {n: j for j, n in enumerate(names)}
    sigma = []
    for j, n in enumerate(names):
        other = _partner_name(n, index)
        if other == n:
            sigma.append(j)
        elif other in index:
            sigma.append(index[other])
        else:
            raise TorchspliceError(f"{where or 'skeleton'}: cannot mirror: joint {n!r} has no partner {other!r} on the "
                                   "other side")
    if len(names) > 1 and all(s == j for j, s in enumerate(sigma)):
        raise TorchspliceError(f"{where or 'skeleton'}: cannot mirror: no joint's name says its side (Left/Right, "
                               "L/R, l_/r_), so no joint has a partner")
    parents = skeleton.parents
    for j, s in enumerate(sigma):
        if sigma[s] != j or (parents[j] >= 0) != (parents[s] >= 0) or (parents[j] >= 0 and sigma[parents[j]] != parents[s]):
            raise TorchspliceError(f"{where or 'skeleton'}: cannot mirror: joints {names[j]!r} and {names[s]!r} pair by "
                                   "name but not in the hierarchy (their parents are not partners)")
    ends = list(skeleton.end_site_parents)
    if sorted(sigma[p] for p in ends) != sorted(ends):
        raise TorchspliceError(f"{where or 'skeleton'}: cannot mirror: end sites on one side only")
    return sigma


def _end_partners(skeleton: Skeleton, sigma: list[int]) -> list[int]:
    """Each end site's partner: the end site of its joint's partner (in order, where a joint has several)."""
    by_joint: dict[int, list[int]] = {}
    for e, p in enumerate(skeleton.end_site_parents):
        by_joint.setdefault(p, []).append(e)
    out = []
    for e, p in enumerate(skeleton.end_site_parents):
        out.append(by_joint[sigma[p]][by_joint[p].index(e)])
    return out


def _horn(a: torch.Tensor, b: torch.Tensor, up: int) -> torch.Tensor:
    """``(3, 3)`` rotation ``R`` minimising ``sum |R a_i - b_i|^2`` over ``(n, 3)`` points (n >= 1)."""
    if a.shape[0] == 1 or torch.linalg.matrix_rank(a, atol=1e-9 * max(1.0, float(a.abs().max()))) < 2:
        u = a[0] / a[0].norm().clamp_min(1e-12)
        v = b[0] / b[0].norm().clamp_min(1e-12)
        axis = torch.linalg.cross(u, v)
        s, c = float(axis.norm()), float(torch.dot(u, v))
        if s < 1e-9:
            if c > 0:
                return torch.eye(3, dtype=a.dtype)
            upv = torch.zeros(3, dtype=a.dtype)
            upv[up] = 1.0
            axis = upv - torch.dot(upv, u) * u  # the perpendicular nearest the up axis
            if float(axis.norm()) < 1e-9:
                axis = torch.zeros(3, dtype=a.dtype)
                axis[(up + 1) % 3] = 1.0
            axis = axis / axis.norm()
            return 2.0 * torch.outer(axis, axis) - torch.eye(3, dtype=a.dtype)  # a half turn about it
        k = axis / s
        K = torch.tensor([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]], dtype=a.dtype)
        return torch.eye(3, dtype=a.dtype) + s * K + (1 - c) * (K @ K)
    u_, _, vh = torch.linalg.svd(b.T @ a)
    d = torch.sign(torch.det(u_ @ vh))
    return u_ @ torch.diag(torch.tensor([1.0, 1.0, float(d)], dtype=a.dtype)) @ vh


def mirror_rest(skeleton: Skeleton, sigma: list[int], axis: int, up: int) -> torch.Tensor:
    """``(J, 3, 3)``: each joint's ``S_k`` (see the module docstring), float64."""
    J = skeleton.num_joints
    M = torch.ones(3, dtype=torch.float64)
    M[axis] = -1.0
    off = skeleton.offsets.to(torch.float64)
    ends = skeleton.end_site_offsets.to(torch.float64)
    end_sigma = _end_partners(skeleton, sigma)
    S = torch.eye(3, dtype=torch.float64).repeat(J, 1, 1)
    for k in range(J):  # once per skeleton, over its joints: not a hot path
        kids = [c for c in skeleton.children(k)]
        a = [off[c] for c in kids] + [ends[e] for e, p in enumerate(skeleton.end_site_parents) if p == k]
        b = [M * off[sigma[c]] for c in kids] + [M * ends[end_sigma[e]] for e, p in enumerate(skeleton.end_site_parents)
                                                  if p == k]
        pairs = [(x, y) for x, y in zip(a, b) if float(x.norm()) > 1e-9 and float(y.norm()) > 1e-9]
        if pairs:
            S[k] = _horn(torch.stack([x for x, _ in pairs]), torch.stack([y for _, y in pairs]), up)
    return S


def mirror_rig(skeleton: Skeleton, up_axis: int | str = 1, axis: int | None = None,
               where: str = "") -> tuple[list[int], torch.Tensor, int]:
    """``(sigma, S, axis)`` of ``skeleton``: its :func:`side_partners`, each joint's
    :func:`mirror_rest` and the world axis negated (default :func:`mirror_axis` of ``up_axis``,
    0, 1, 2 or ``"x"``, ``"y"``, ``"z"``). Once per skeleton where many clips are mirrored."""
    up = "xyz".index(up_axis.lower()) if isinstance(up_axis, str) else int(up_axis)
    ax = mirror_axis(up) if axis is None else int(axis)
    sigma = side_partners(skeleton, where)
    return sigma, mirror_rest(skeleton, sigma, ax, up), ax


def mirror_motion(motion: Motion, up_axis: int | str = 1, axis: int | None = None, name: str | None = None,
                  where: str = "", rig: tuple[list[int], torch.Tensor, int] | None = None) -> Motion:
    """The mirror image of ``motion`` on its own skeleton (see the module docstring).

    Args:
        motion: any clip: ``rotations`` ``(T, J, 4)`` WXYZ, ``root_translation`` ``(T, 3)``,
            optional ``translations`` ``(T, J, 3)``.
        up_axis: the data's up axis, 0, 1 or 2 or ``"x"``, ``"y"``, ``"z"`` (the dataset spec's).
        axis: the world axis to negate (default :func:`mirror_axis`).
        name: the result's name (default the clip's, left and right swapped by :func:`mirror_text`).
        where: what names the clip in messages (default its name).
        rig: the skeleton's :func:`mirror_rig` (``up_axis`` and ``axis`` then unused), where the
            caller mirrors many clips of one skeleton; computed when ``None``.

    Returns a :class:`Motion` in the clip's dtype whose joint ``j`` stands at the reflection of
    joint ``sigma(j)``; its labels by :func:`mirror_labels` (``mirror_of`` naming the take).
    Vectorised over frames and joints.
    """
    sk = motion.skeleton
    sigma, S, ax = mirror_rig(sk, up_axis, axis, where or motion.name or "clip") if rig is None else rig
    S = S.to(torch.float64)
    dtype = motion.rotations.dtype
    rot = motion.rotations.to(torch.float64)
    root = motion.root_translation.to(torch.float64)
    trans = None if motion.translations is None else motion.translations.to(torch.float64)
    pos, grot = forward_kinematics(rot, root, sk.offsets.to(torch.float64), sk.parents, trans)
    M = torch.ones(3, dtype=torch.float64)
    M[ax] = -1.0
    G = quat_to_rotmat(grot[:, sigma])  # (T, J, 3, 3) the partners'
    G2 = (M[:, None] * G * M[None, :]) @ S  # M G M S
    q2 = rotmat_to_quat(G2)
    parents = list(sk.parents)
    par = torch.tensor([max(p, 0) for p in parents])
    local = quat_mul(quat_conj(q2[:, par]), q2)
    local[:, 0] = q2[:, 0]
    local = _continuous(local)
    p2 = pos[:, sigma] * M
    trans2 = None
    if trans is not None:
        rel = p2 - p2[:, par]
        trans2 = torch.einsum("tjba,tjb->tja", G2[:, par], rel)  # G'_parent^T (p'_j - p'_parent)
        animated = torch.tensor(sk.translation_animated)
        trans2 = torch.where(animated[None, :, None], trans2, sk.offsets.to(torch.float64)[None])
        trans2[:, 0] = p2[:, 0]
    labels = mirror_labels(motion.labels, motion.name, spliced=(motion.role == "spliced") if motion.role else None)
    return replace(motion, rotations=local.to(dtype), root_translation=p2[:, 0].to(dtype),
                   translations=None if trans2 is None else trans2.to(dtype),
                   name=mirror_text(motion.name) if name is None else name, labels=labels)


def _continuous(q: torch.Tensor) -> torch.Tensor:
    """``(T, J, 4)`` quaternions with signs chosen so that the first frame has ``w >= 0`` and each
    frame is in the hemisphere of the one before (a cumulative product of the flips: no loop)."""
    if q.shape[0] == 0:
        return q
    flip = torch.ones(q.shape[:2], dtype=q.dtype)
    flip[0] = torch.where(q[0, :, 0] < 0, -1.0, 1.0)
    if q.shape[0] > 1:
        flip[1:] = torch.where((q[1:] * q[:-1]).sum(-1) < 0, -1.0, 1.0)
    return q * torch.cumprod(flip, 0)[..., None]


def mirror_labels(labels: dict, name: str, spliced: bool | None = None) -> dict:
    """A mirror image's labels: text values' left and right swapped by :func:`mirror_text`,
    except :data:`IDENTITY_LABELS` (bare or after ``action.`` / ``locomotion.``) and a spliced
    clip's ``locomotion`` and ``action``; ``mirror_of`` the take the clip ``name`` comes from
    (its ``mirror_of`` when it is a mirror image already, else its ``split_from`` when it is a
    window of a take, else ``name``), so that splits keep a mirror image with its original.
    ``spliced``: whether the clip is a spliced clip (``None``: guessed from a ``method`` label)."""
    if spliced is None:
        spliced = "method" in labels
    out = {}
    for k, v in labels.items():
        bare = k.split(".", 1)[1] if k.startswith(("action.", "locomotion.")) else k
        keep = (bare in IDENTITY_LABELS or (k in ("locomotion", "action") and spliced)  # a spliced clip's sources
                or not isinstance(v, str))
        out[k] = v if keep else mirror_text(v)
    out["mirror_of"] = labels.get("mirror_of") or labels.get("split_from") or name
    return out


def mirror_text(text: str) -> str:
    """``text`` with left and right (and clockwise and counterclockwise) swapped, as words or
    parts of compound words (``wave-right-hand`` -> ``wave-left-hand``), keeping their case.
    ``anticlockwise`` becomes ``clockwise``, whose mirror is ``counterclockwise``: twice gives
    the same meaning, not always the same word."""
    def swap(m: re.Match) -> str:
        word = m.group(0)
        other = _WORDS.get(word.lower())
        if other is None:
            return word
        return other.upper() if word.isupper() else other.capitalize() if word[:1].isupper() else other

    return _SIDE_WORD.sub(swap, text)

