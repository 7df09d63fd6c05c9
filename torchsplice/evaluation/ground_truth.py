"""Error of a spliced clip against a captured ground truth.

Bandai Namco's style x locomotion sets hold the same style captured during several
locomotions: the upper body of a styled straight walk spliced onto a normal-style turn can be
compared with the same style captured turning. The error is the mean distance of the
upper-body joints (file units), each clip's joints expressed in its own root heading frame
(origin at the trajectory joint, up axis up, lateral axis along the hips), after aligning the
capture to the result in time with the same lower-body timewarp the splice uses.

:func:`best_posture_error` is an oracle bound for judging methods: the same error after the
one constant rotation of the upper body about the pelvis (in the heading frame) that brings
each result closest to its capture. No method that keeps the action's motion and changes
only its posture by a constant rotation can do better.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import torch

from ..align.horn import horn_rotation_matrix
from ..core.motion import Motion
from ..specs import SkeletonRoles
from ..kinematics.heading import heading_points
from ..splice.clips import clips_to_tensors, resample_motion
from ..splice.heck import time_align
from ..splice.options import AlignOptions

__all__ = ["GroundTruthTriple", "upper_body_error", "best_posture_error", "bandai_namco_triples"]


@dataclass(frozen=True)
class GroundTruthTriple:
    """Clip names: the action (upper-body source), the locomotion, and the captured combination."""

    action: str
    locomotion: str
    capture: str


def _heading_local(positions: torch.Tensor, roles: SkeletonRoles) -> torch.Tensor:
    """``(B, T, U, 3)`` upper-body joints in the root heading frame."""
    return heading_points(positions, roles.hips, roles.root, roles.upper_body, roles.up_axis)[1]


def _aligned_upper_bodies(results: list[Motion], captures: list[Motion], roles: SkeletonRoles,
                          options: AlignOptions | None):
    """Upper bodies ``(B, T, U, 3)`` of results and time-aligned captures in their own heading
    frames, and ``(B, T)`` float weights, 1 on the aligned frames."""
    options = options or AlignOptions()
    fps = results[0].fps
    sk = results[0].skeleton
    R = clips_to_tensors(results, sk, dtype=torch.float64)
    C = clips_to_tensors([resample_motion(c.to(torch.float64), fps) for c in captures], sk, dtype=torch.float64)
    al = time_align(R, C, roles, options, fps)
    Cr = C.shift(al.crop).at_times(al.curve, al.frames, sk)
    a = _heading_local(R.positions[:, : Cr.positions.shape[1]], roles)
    b = _heading_local(Cr.positions, roles)
    valid = (torch.arange(a.shape[1])[None, :] < al.frames[:, None]).to(a.dtype)
    return a, b, valid


def _mean_error(a: torch.Tensor, b: torch.Tensor, valid: torch.Tensor) -> torch.Tensor:
    """``(B,)`` mean joint distance between ``(B, T, U, 3)`` clouds over the valid frames."""
    err = (a - b).norm(dim=-1).mean(-1)  # (B, T)
    return (err * valid).sum(1) / valid.sum(1)


def upper_body_error(results: list[Motion], captures: list[Motion], roles: SkeletonRoles,
                     options: AlignOptions | None = None) -> torch.Tensor:
    """``(B,)`` mean upper-body joint error (file units) of each result against its capture.

    Results and captures are paired by position; a capture is resampled to its result's frame
    rate, time-aligned to it on the lower bodies, and compared over the aligned frames.
    """
    return _mean_error(*_aligned_upper_bodies(results, captures, roles, options))


def best_posture_error(results: list[Motion], captures: list[Motion], roles: SkeletonRoles,
                       options: AlignOptions | None = None) -> torch.Tensor:
    """``(B,)`` :func:`upper_body_error` after the best constant posture change (an oracle bound).

    Per pair, one rotation ``R`` of the result's upper body about its pelvis joint, in the
    heading frame and the same for every frame, is chosen by Horn's method to bring the
    result's joints (relative to the pelvis, over all aligned frames) closest in the least
    squares sense to the capture's; the error is then measured as in :func:`upper_body_error`.
    It minimises squared distances, not the mean distance reported, so it is nearly always (not
    by construction) below the plain error; it is 0 for a result that is its capture turned by
    a constant rotation about the pelvis.
    """
    a, b, valid = _aligned_upper_bodies(results, captures, roles, options)
    return _best_posture_clouds(a, b, valid, list(roles.upper_body).index(roles.pelvis))


def _best_posture_clouds(a: torch.Tensor, b: torch.Tensor, valid: torch.Tensor, k: int) -> torch.Tensor:
    """``(B,)`` :func:`_mean_error` of clouds ``a`` ``(B, T, U, 3)`` against ``b`` after the
    constant rotation of each ``a`` about its joint ``k`` (per frame) that best fits ``b`` (least
    squares over the frames weighted by ``valid`` ``(B, T)``)."""
    pa, pb = a - a[:, :, k:k + 1], b - b[:, :, k:k + 1]
    B, T, U, _ = a.shape
    w = valid[:, :, None].expand(B, T, U).reshape(B, T * U)
    R = horn_rotation_matrix(pa.reshape(B, T * U, 3), pb.reshape(B, T * U, 3), w / w.sum(1, keepdim=True))
    turned = torch.einsum("bij,btuj->btui", R, pa) + a[:, :, k:k + 1]
    return _mean_error(turned, b, valid)


_BANDAI = re.compile(r"^dataset-(\d+)_(.+?)_([^_]+)_(\d+)$")


def bandai_namco_triples(names) -> list[GroundTruthTriple]:
    """Ground-truth triples among Bandai Namco clip names (file stems).

    For each dataset and style other than ``normal``: the style's straight ``walk`` is the
    action, every other locomotion content captured in ``normal`` style is a locomotion, and
    the same content captured in the style is the ground truth.
    """
    table: dict[tuple[str, str, str], str] = {}
    for n in sorted(Path(str(n)).stem for n in names):
        m = _BANDAI.match(n)
        if m:
            table.setdefault((m[1], m[2], m[3]), n)
    triples = []
    for (ds, content, style), action in sorted(table.items()):
        if content != "walk" or style == "normal":
            continue
        for (ds2, c2, s2), loco in sorted(table.items()):
            if ds2 == ds and s2 == "normal" and c2 != "walk" and (ds, c2, style) in table:
                triples.append(GroundTruthTriple(action, loco, table[(ds, c2, style)]))
    return triples
