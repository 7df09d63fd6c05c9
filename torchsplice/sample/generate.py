"""The built-in sample: procedurally generated walking clips on a standard humanoid skeleton.

A newcomer's first run needs motion without downloads; this module makes it. Every clip is
generated from a handful of gait and path parameters, deterministically (fixed seeds; the same
output on every call), and vectorised over frames with numpy (the only Python loops run over
joints, feet and clips).

The parts, each its own module: the skeleton (:mod:`.skeleton`), the clips' parameters
(:mod:`.clips`), the path, the feet, the pelvis and the legs (:mod:`.locomotion`), the trunk, the
head and the arms (:mod:`.actions`), and small numpy helpers (:mod:`.numeric`); this module puts
one clip together from them and makes the :class:`~torchsplice.core.motion.Motion` objects.

Conventions:

- **Y up, centimetres**, the floor is ``y = 0``; the character faces **+Z** at frame 0 and its
  left is **+X**. Every clip starts at the origin.
- Rotations are unit quaternions in **WXYZ** order (scalar first), local to the parent joint,
  continuous in time (no sign flips between frames).
- 30 frames per second.

The skeleton (:func:`sample_skeleton`) is a 22-joint human, about 175 cm tall, whose rest
pose stands upright with the **arms hanging straight down** and every joint's local axes
aligned with the world (X left, Y up, Z forward). Consequences used throughout: a joint's
rotation about its local X axis pitches the bone below it forward or back (negative X swings
an arm forward and flexes an elbow; positive X flexes a knee and lifts a heel); rotation about
Z raises the arms sideways (positive Z for the left arm, negative for the right).

How the clips are made (:func:`sample_motions`):

1. A ground path (position and heading, integrated from a speed and a turn rate on a fine
   time grid) and a gait cycle coordinate ``c(t)`` (one unit = one gait cycle = two steps;
   the left foot strikes the ground at integer ``c``, the right at half-integers).
2. Foot plants: each stance of each foot gets one fixed ground position beside the path,
   taken where the pelvis passes over it. During stance the foot rolls heel - flat - toe
   (heel rocker, planted ankle, heel-off pivoting about the ball), so the ankle is exactly
   still through flat foot; during swing it follows a smooth arc to the next plant.
3. The pelvis follows the path with sway, transverse twist, list and tilt; its height is a
   nominal bob softly clipped (smooth minimum) to what both legs can reach, then smoothed
   from below (never higher than the legs allow), so it dips in double support as real
   walkers do.
4. Analytic two-bone IK puts each hip-knee-ankle chain onto its foot target, the knee
   pointing along the foot; the foot and toe take the rolled foot orientation.
5. The upper body: spine counter-rotation against the pelvis (thorax twist opposite the
   pelvis, so each arm swings forward with the opposite leg), a per-clip trunk lean, the head
   looking into turns, and the arms either swinging or doing the clip's action.

Every joint's rotation keeps its middle BVH Euler angle (X, of the ``Zrotation Xrotation
Yrotation`` channels) under about 82 degrees: knees and elbows flex about X, and beyond 90
the Euler channels of a written BVH file would flip through gimbal lock. So the jog's knees
bend a little less than a real jogger's, and the punch's guard (elbows past 90) turns each
upper arm 90 degrees about its length so that the elbow hinges about its local Z instead.

Clips (name: role): ``walk_straight``, ``walk_curve``, ``turn_sharp``, ``sidestep``, ``jog``
(locomotion); ``carry_box``, ``carry_cup``, ``wave``, ``punch``, ``arms_out`` (actions,
performed while walking, so their lower bodies are real locomotion too). Gait parameters
(stride, cadence, phase at frame 0, slow cadence wobble) differ per clip, so that time
alignment has something to do.
"""


from __future__ import annotations

import numpy as np
import torch

from ..core.motion import Motion
from ..core.rotations import rotmat_to_quat
from ..core.skeleton import Skeleton
from .actions import arms, trunk_and_head
from .clips import CLIPS, SAMPLE_CLIPS, ClipSpec
from .locomotion import foot_targets, leg_rotations, pelvis_motion, timeline
from .skeleton import JOINT_NAMES, sample_skeleton

__all__ = [
    "SAMPLE_FPS",
    "SAMPLE_SOURCE",
    "SAMPLE_CLIPS",
    "sample_skeleton",
    "sample_motions",
    "sample_motion",
]

SAMPLE_FPS = 30.0
"""Frame rate of every sample clip."""

SAMPLE_SOURCE = "torchsplice.sample"
"""The ``source`` every sample clip carries."""


def _generate(clip: ClipSpec) -> tuple[np.ndarray, np.ndarray]:
    """Local rotation matrices ``(T, 22, 3, 3)`` and root translations ``(T, 3)`` of one clip:
    its path and gait clock, the feet's targets, the pelvis, the legs by IK onto the feet, the
    trunk and head, then the arms (see the module docstring's steps)."""
    fps = SAMPLE_FPS
    T = int(round(clip.duration * fps))
    gait, up = clip.gait, clip.upper
    rng = np.random.default_rng(clip.seed)
    tl = timeline(clip, T, fps)
    feet = [foot_targets(tl, gait, side) for side in (0, 1)]
    pelvis = pelvis_motion(tl, gait, feet)
    local = np.broadcast_to(np.eye(3), (T, len(JOINT_NAMES), 3, 3)).copy()
    local[:, 0] = pelvis.rotation
    leg_rotations(local, tl, pelvis, feet)
    trunk_and_head(local, tl, gait, up, pelvis, rng)
    arms(local, tl, gait, up, pelvis, rng)
    return local, pelvis.position


def _to_quaternions(local: np.ndarray, dtype: torch.dtype) -> torch.Tensor:
    """``(T, J, 3, 3)`` rotation matrices to ``(T, J, 4)`` WXYZ quaternions, sign-continuous in time."""
    q = rotmat_to_quat(torch.from_numpy(local))
    dots = (q[1:] * q[:-1]).sum(-1)
    flips = torch.cat((torch.ones_like(q[:1, :, 0]), torch.where(dots < 0, -1.0, 1.0).to(q)))
    q = q * torch.cumprod(flips, dim=0)[..., None]
    return q.to(dtype)


def _make_motion(clip: ClipSpec, skeleton: Skeleton, dtype: torch.dtype) -> Motion:
    """Generate ``clip`` on ``skeleton`` as a :class:`Motion` with tensors of ``dtype``."""
    local, root = _generate(clip)
    return Motion(
        skeleton=skeleton,
        rotations=_to_quaternions(local, dtype),
        root_translation=torch.from_numpy(root).to(dtype),
        fps=SAMPLE_FPS,
        name=clip.name,
        source=SAMPLE_SOURCE,
        role=clip.role,
        labels=dict(clip.labels),
    )


def sample_motions(dtype: torch.dtype = torch.float32) -> list[Motion]:
    """Every sample clip, generated afresh (deterministic: the same values on every call).

    Clips, in :data:`SAMPLE_CLIPS` order, all 30 fps, 5-7 s, starting at the origin facing +Z
    (Y up, cm):

    - locomotion (``role="locomotion"``): ``walk_straight``; ``walk_curve`` (a left curve, about
      27 deg/s after a ramp, some 160 degrees in all); ``turn_sharp`` (a 120-degree turn to the
      right within 2 s, slowing down); ``sidestep`` (facing +Z, travelling left along +X);
      ``jog`` (with flight phases);
    - actions while walking (``role="action"``): ``carry_box`` (trunk leaning back, the
      hips-to-neck line some 10-11 degrees behind vertical against about 2 forward when
      walking, both arms holding a box in front, slower shorter steps); ``carry_cup`` (right
      forearm raised and held steady in the heading frame, gentle S-curve path); ``wave``
      (right arm waving overhead); ``punch`` (alternating punches, the trunk turning into
      each); ``arms_out`` (arms held out sideways).

    Each :class:`Motion` has ``rotations`` ``(T, 22, 4)`` (local, unit WXYZ quaternions,
    sign-continuous in time), ``root_translation`` ``(T, 3)`` (cm), ``translations=None``,
    ``fps=30``, ``name``, ``role``, ``labels`` (``content``, ``kind`` and ``path`` or ``gait``)
    and ``source="torchsplice.sample"``; all share one :func:`sample_skeleton`.

    Args:
        dtype: floating dtype of the returned tensors (computed in float64).
    """
    skeleton = sample_skeleton()
    return [_make_motion(clip, skeleton, dtype) for clip in CLIPS]


def sample_motion(name: str, dtype: torch.dtype = torch.float32) -> Motion:
    """One sample clip by name (one of :data:`SAMPLE_CLIPS`); see :func:`sample_motions`."""
    for clip in CLIPS:
        if clip.name == name:
            return _make_motion(clip, sample_skeleton(), dtype)
    raise KeyError(f"no sample clip {name!r}; the sample has: {', '.join(SAMPLE_CLIPS)}")
