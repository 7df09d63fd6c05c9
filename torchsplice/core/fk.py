"""Batched forward kinematics on torch tensors.

Any number of leading batch dimensions (``...``: e.g. clips ``B`` and frames ``T``) is
accepted. Quaternions are unit WXYZ; rotation matrices act on column vectors. The Python
loop runs over the depth of the hierarchy (about 8 for a human skeleton), never over clips
or frames; every step is a batched tensor operation, so the same code runs on CPU or CUDA
and in float32 or float64 (the dtype and device of ``rotations``).
"""

from __future__ import annotations

from typing import Sequence

import torch

from .quat_formulas import qmul as _qmul, qrot as _qrot
from .rotations import quat_apply
from .skeleton import hierarchy_levels

__all__ = ["forward_kinematics", "end_site_positions"]


def forward_kinematics(
    rotations: torch.Tensor,
    root_translation: torch.Tensor,
    offsets: torch.Tensor,
    parents: Sequence[int],
    translations: torch.Tensor | None = None,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Global joint positions and rotations from local ones.

    Args:
        rotations: ``(..., J, 4)`` local joint rotations, unit WXYZ quaternions.
        root_translation: ``(..., 3)`` world position of joint 0.
        offsets: ``(J, 3)`` rest translations of each joint in its parent's frame.
        parents: ``J`` parent indices, ``-1`` for joint 0, topologically ordered.
        translations: optional ``(..., J, 3)`` animated local translations that replace
            ``offsets`` (joints that are not animated must hold their offset); row 0 is
            ignored in favour of ``root_translation``.

    Returns:
        ``positions`` ``(..., J, 3)`` in world units and ``global_rotations`` ``(..., J, 4)``,
        unit WXYZ quaternions mapping each joint's frame to the world
        (:func:`~torchsplice.core.rotations.quat_to_rotmat` gives matrices).

    Padding frames (any finite values) are computed like real ones; masks stay with the caller.
    Internally the work runs on component-major ``(4, J, N)`` arrays so that every
    elementwise kernel streams over the ``N = prod(...)`` frames contiguously.
    """
    J = len(parents)
    if rotations.shape[-2:] != (J, 4):
        raise ValueError(f"rotations must be (..., {J}, 4) for {J} joints, got {tuple(rotations.shape)}")
    batch = rotations.shape[:-2]
    if root_translation.shape != batch + (3,):
        raise ValueError(f"root_translation must be {tuple(batch) + (3,)}, got {tuple(root_translation.shape)}")
    if offsets.shape != (J, 3):
        raise ValueError(f"offsets must be ({J}, 3), got {tuple(offsets.shape)}")
    if translations is not None and translations.shape != batch + (J, 3):
        raise ValueError(f"translations must be {tuple(batch) + (J, 3)}, got {tuple(translations.shape)}")
    N = root_translation[..., 0].numel()
    q = rotations.reshape(N, J, 4).permute(2, 1, 0).contiguous()  # (4, J, N)
    if translations is not None:
        t = translations.reshape(N, J, 3).permute(2, 1, 0).contiguous()  # (3, J, N)
    else:
        t = offsets.to(rotations)[:, :, None].permute(1, 0, 2).expand(3, J, N)
    gq: list[tuple] = [()] * J  # per joint: tuple of 4 (N,) tensors
    gp: list[tuple] = [()] * J  # per joint: tuple of 3 (N,) tensors
    gq[0] = tuple(q[:, 0])
    gp[0] = tuple(root_translation.reshape(N, 3).t())
    for level in hierarchy_levels(tuple(int(p) for p in parents))[1:]:
        idx = list(level)
        par = [parents[j] for j in idx]
        pq = tuple(torch.stack([gq[p][c] for p in par]) for c in range(4))  # 4 x (k, N)
        pp = tuple(torch.stack([gp[p][c] for p in par]) for c in range(3))
        lq, lt = q[:, idx], t[:, idx]
        nq = _qmul(pq, tuple(lq))
        off = _qrot(pq, tuple(lt))
        npos = tuple(a + b for a, b in zip(pp, off))
        for k, j in enumerate(idx):
            gq[j] = tuple(c[k] for c in nq)
            gp[j] = tuple(c[k] for c in npos)
    rot = torch.stack([torch.stack(g) for g in gq], 1)  # (4, J, N)
    pos = torch.stack([torch.stack(g) for g in gp], 1)  # (3, J, N)
    return pos.permute(2, 1, 0).reshape(batch + (J, 3)), rot.permute(2, 1, 0).reshape(batch + (J, 4))


def end_site_positions(
    positions: torch.Tensor,
    global_rotations: torch.Tensor,
    end_site_parents: Sequence[int],
    end_site_offsets: torch.Tensor,
) -> torch.Tensor:
    """World positions ``(..., E, 3)`` of end sites from FK output.

    Args:
        positions: ``(..., J, 3)`` joint positions from :func:`forward_kinematics`.
        global_rotations: ``(..., J, 4)`` global WXYZ quaternions from :func:`forward_kinematics`.
        end_site_parents: ``E`` joint indices the end sites hang from.
        end_site_offsets: ``(E, 3)`` offsets in those joints' frames.
    """
    par = torch.as_tensor(list(end_site_parents), dtype=torch.long, device=positions.device)
    q = global_rotations.index_select(-2, par)
    return positions.index_select(-2, par) + quat_apply(q, end_site_offsets.to(positions))
