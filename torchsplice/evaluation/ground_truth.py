"""Error of a spliced clip against a captured ground truth.

Bandai Namco's style x locomotion sets hold the same style captured during several
locomotions: the upper body of a styled straight walk spliced onto a normal-style turn can be
compared with the same style captured turning. The error is the mean distance of the
upper-body joints (file units), each clip's joints expressed in its own root heading frame
(origin at the trajectory joint, up axis up, lateral axis along the hips), after aligning the
capture to the result in time with the same lower-body timewarp the splice uses.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import torch

from ..core.motion import Motion
from ..specs import SkeletonRoles
from ..kinematics.heading import heading_frame, to_heading_frame
from ..splice.clips import clips_to_tensors, resample_motion
from ..splice.heck import AlignOptions, time_align

__all__ = ["GroundTruthTriple", "upper_body_error", "bandai_namco_triples"]


@dataclass(frozen=True)
class GroundTruthTriple:
    """Clip names: the action (upper-body source), the locomotion, and the captured combination."""

    action: str
    locomotion: str
    capture: str


def _heading_local(positions: torch.Tensor, roles: SkeletonRoles) -> torch.Tensor:
    """``(B, T, U, 3)`` upper-body joints in the root heading frame."""
    H = heading_frame(positions[:, :, roles.hips[0]], positions[:, :, roles.hips[1]], roles.up_axis)
    return to_heading_frame(positions[:, :, list(roles.upper_body)], positions[:, :, roles.root], H)


def upper_body_error(results: list[Motion], captures: list[Motion], roles: SkeletonRoles,
                     options: AlignOptions | None = None) -> torch.Tensor:
    """``(B,)`` mean upper-body joint error (file units) of each result against its capture.

    Results and captures are paired by position; a capture is resampled to its result's frame
    rate, time-aligned to it on the lower bodies, and compared over the aligned frames.
    """
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
    err = (a - b).norm(dim=-1).mean(-1)  # (B, T)
    return (err * valid).sum(1) / valid.sum(1)


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
