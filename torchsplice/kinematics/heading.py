"""Heading frames: the character's facing in the floor plane, from its hips.

A heading frame has its origin wherever the caller puts it (usually the pelvis), its up axis
along the world's up axis (``up_axis`` 0, 1 or 2; Y for every shipped dataset), and its
*lateral* axis along the floor projection of the hip vector (left hip minus right hip). For
``up_axis = 1`` the heading frame's x is lateral, y is up and z = x cross y is forward (for a
skeleton whose left is +x when facing +z). For other up axes the lateral axis is the first
axis that is not up, and the third is chosen to keep the frame right-handed.

Quaternions are unit WXYZ; ``H`` maps heading-frame coordinates to world coordinates.
"""

from __future__ import annotations

import torch

from ..core.rotations import quat_apply, quat_conj, rotmat_to_quat

__all__ = ["heading_frame", "to_heading_frame", "lateral_axis"]


def lateral_axis(up_axis: int) -> int:
    """The heading frame's lateral (hip-vector) axis index for a given up axis."""
    if up_axis not in (0, 1, 2):
        raise ValueError(f"up_axis must be 0, 1 or 2, got {up_axis}")
    return 1 if up_axis == 0 else 0


def heading_frame(left_hip: torch.Tensor, right_hip: torch.Tensor, up_axis: int = 1) -> torch.Tensor:
    """``(..., 4)`` WXYZ rotations of the heading frames, from ``(..., 3)`` hip positions.

    The hip vector's floor projection must not vanish (it does not for a standing human).
    """
    if left_hip.shape[-1] != 3 or left_hip.shape != right_hip.shape:
        raise ValueError(f"hips must be matching (..., 3) tensors, got {tuple(left_hip.shape)} and {tuple(right_hip.shape)}")
    lat = lateral_axis(up_axis)
    third = 3 - lat - up_axis
    v = left_hip - right_hip
    up = torch.zeros_like(v)
    up[..., up_axis] = 1.0
    lateral = v - (v * up).sum(-1, keepdim=True) * up
    lateral = lateral / lateral.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    cyclic = (up_axis - lat) % 3 == 1  # (lat, up, third) an even permutation
    other = torch.linalg.cross(lateral, up, dim=-1) * (1.0 if cyclic else -1.0)
    cols = [None, None, None]
    cols[lat], cols[up_axis], cols[third] = lateral, up, other
    return rotmat_to_quat(torch.stack(cols, dim=-1))


def to_heading_frame(points: torch.Tensor, origin: torch.Tensor, frame: torch.Tensor) -> torch.Tensor:
    """Express ``(..., K, 3)`` world points in heading frames.

    Args:
        points: ``(..., K, 3)`` world positions.
        origin: ``(..., 3)`` the frame's origin in the world (e.g. the pelvis).
        frame: ``(..., 4)`` heading rotations from :func:`heading_frame`.
    """
    return quat_apply(quat_conj(frame)[..., None, :], points - origin[..., None, :])
