"""Headings: the character's facing in the floor plane, from its hips (every torch path
computes it here; the compiled kernels' twin is :mod:`torchsplice.cpu.heading`).

Two forms, for two uses, both from the hip vector ``left hip - right hip``:

- the heading *frame* (:func:`heading_frame`, :func:`hip_heading_frame`, points expressed in it
  by :func:`to_heading_frame` and :func:`heading_points`): a rotation, for posture transfer and
  the evaluation's body-relative measures;
- the heading *angle* (:func:`heading_from_hips`): a number, for the frame distance's heading
  restriction (:mod:`torchsplice.align.distance`), where only differences of headings count.

They are not one formula: the angle is ``atan2`` of ``(left - right) x up`` on the floor axes
(:func:`floor_axes`), unnormalised, while the frame normalises the hip vector's floor projection
and picks its third axis to stay right-handed. For Y up the frame's third axis is the angle's
forward direction; for X or Z up it is its opposite. Each keeps its own formula so that every
result stays as it was, bit for bit.

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

__all__ = ["heading_frame", "to_heading_frame", "lateral_axis", "third_axis", "hip_heading_frame", "heading_points",
           "floor_axes", "heading_from_hips"]


def lateral_axis(up_axis: int) -> int:
    """The heading frame's lateral (hip-vector) axis index for a given up axis."""
    if up_axis not in (0, 1, 2):
        raise ValueError(f"up_axis must be 0, 1 or 2, got {up_axis}")
    return 1 if up_axis == 0 else 0


def third_axis(up_axis: int) -> int:
    """The heading frame's third axis index (neither lateral nor up: z, forward, for Y up)."""
    return 3 - lateral_axis(up_axis) - up_axis


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


def hip_heading_frame(positions: torch.Tensor, hips: tuple[int, int] | list[int], up_axis: int = 1) -> torch.Tensor:
    """``(..., 4)`` heading frames of ``(..., J, 3)`` joint positions, from joints ``hips`` (left, right)."""
    return heading_frame(positions[..., hips[0], :], positions[..., hips[1], :], up_axis)


def heading_points(positions: torch.Tensor, hips, origin: int, joints, up_axis: int = 1):
    """``(H, points)``: the heading frames ``(..., 4)`` of ``(..., J, 3)`` joint positions
    (:func:`hip_heading_frame`) and joints ``joints`` in them, ``(..., K, 3)``, around joint ``origin``."""
    H = hip_heading_frame(positions, hips, up_axis)
    return H, to_heading_frame(positions[..., list(joints), :], positions[..., origin, :], H)


def floor_axes(up_axis: int = 1) -> tuple[int, int]:
    """``(a1, a2) = ((up_axis + 1) % 3, (up_axis + 2) % 3)``; ``ValueError`` unless ``up_axis`` is 0, 1 or 2."""
    if up_axis not in (0, 1, 2) or isinstance(up_axis, bool):
        raise ValueError(f"up_axis must be 0, 1 or 2, got {up_axis!r}")
    return (up_axis + 1) % 3, (up_axis + 2) % 3


def heading_from_hips(left_hip: torch.Tensor, right_hip: torch.Tensor, up_axis: int = 1) -> torch.Tensor:
    """Facing direction ``(...)`` in radians from ``(..., 3)`` hip positions.

    ``forward = (left_hip - right_hip) x up`` (in the floor plane), and the heading is
    ``atan2(forward[a2], forward[a1])`` (:func:`floor_axes`): for Y up, a character whose left
    hip is towards +X faces +Z, heading 0. (Not the angle of :func:`heading_frame`'s third axis:
    see the module docstring.)
    """
    if left_hip.shape[-1:] != (3,) or right_hip.shape[-1:] != (3,):
        raise ValueError(f"hips must have shape (..., 3), got {tuple(left_hip.shape)} and {tuple(right_hip.shape)}")
    a1, a2 = floor_axes(up_axis)
    d = left_hip - right_hip
    # (d x e_up)[a1] = d[a2], (d x e_up)[a2] = -d[a1]
    return torch.atan2(-d[..., a1], d[..., a2])
