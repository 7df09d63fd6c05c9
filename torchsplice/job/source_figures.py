"""The plan's figures of its source clips, against which each result is judged: how a clip puts
a hand inside its body (``penetration``, ``penetration_depth`` in the skeleton's units: the
columns convert it to cm) and the jerk of its upper body (m/s^3), computed once per clip at
plan time by the job's backend, as the results' are.
"""

from __future__ import annotations

import math

import numpy as np

from ..ops.body import body_of
from ..ops.plausibility import figure_joints
from ..ops.units import centimetres
from ..specs import DatasetSpec

__all__ = ["source_figures", "scales"]


def scales(spec_json: str) -> tuple[int, float, float]:
    """``(up axis index, units per metre, centimetres per unit)`` of a group's spec (NaN for
    unknown units: figures in metres or centimetres are then NaN)."""
    spec = DatasetSpec.from_json(spec_json)
    cm = centimetres(spec.units)
    return "xyz".index(spec.up_axis), 100.0 / cm, cm


def source_figures(config, sources, groups, clips: dict, sk_l) -> None:
    """Record in ``clips`` (:class:`~torchsplice.job.plan.PlanClip`) each clip's figures on its
    group's skeleton (:meth:`~torchsplice.splice.backends.Backend.inside_body` and
    :meth:`~torchsplice.splice.backends.Backend.figures`), 64 clips at a time."""
    backend = config.splice_backend()
    for g in groups:
        skeleton = sk_l[g.skeleton]
        roles = g.roles(skeleton)
        body = body_of(skeleton, roles)
        joints = figure_joints(skeleton, roles)
        up, per_metre, _ = scales(g.spec)
        for b in range(0, len(g.clips), 64):
            chunk = g.clips[b:b + 64]
            motions = [sources.motion(k) for k in chunk]
            rot = np.concatenate([m.rotations.detach().cpu().numpy() for m in motions]).astype(np.float32)
            trans = np.concatenate([m.local_translations().detach().cpu().numpy() for m in motions]).astype(np.float32)
            lengths = [m.num_frames for m in motions]
            share, depth = backend.inside_body(rot, trans, lengths, skeleton, body)
            jerk = backend.figures(rot, trans, lengths, [m.fps for m in motions], skeleton, joints, up,
                                   per_metre if math.isfinite(per_metre) else 1.0)["jerk"]
            for k, sh, d, j in zip(chunk, share.tolist(), depth.tolist(), jerk.tolist()):
                clips[k].penetration, clips[k].penetration_depth = sh, d  # the skeleton's units
                clips[k].jerk = j if math.isfinite(per_metre) else math.nan
