"""Best rotation between two corresponding point clouds (Horn 1987), batched.

Heck et al. 2006 (Sections 3.2 and 3.3) align the upper bodies of two frames, and the
average postures of two clips, by the 3D rotation ``R`` that minimises

    sum_k w_k |target_k - R source_k|^2

over proper rotations (``det R = +1``), both clouds already having their pivot at the origin
(no translation is estimated). Conventions follow :mod:`torchsplice.core.rotations`:
quaternions are unit WXYZ with ``w >= 0``, matrices act on column vectors, any number of
leading batch dimensions, float32 and float64, ``ValueError`` on bad shapes.

Two equivalent closed forms are given:

- :func:`horn_rotation_matrix` / :func:`horn_rotation` (the default): the SVD of the
  cross-covariance ``H = sum_k w_k source_k target_k^T = U S V^T`` gives
  ``R = V diag(1, 1, det(V U^T)) U^T`` (the determinant correction keeps ``R`` proper when the
  best orthogonal map would be a reflection).
- :func:`horn_rotation_eig`: Horn's original quaternion method, the eigenvector of the
  largest eigenvalue of a symmetric 4x4 matrix ``N`` built from ``H``.

Degenerate inputs are handled deterministically by the SVD form: ``H ~ 0`` (e.g. all points
at the origin, or all weights zero) gives the identity; a rank-1 ``H`` (collinear clouds,
or a single point) gives the smallest rotation taking the source line onto the target line
(so identical collinear clouds give the identity). The minimiser is then not unique, but the
one returned is a valid minimiser and never NaN. The eigen form makes no such promise.
"""

from __future__ import annotations

import torch

from ..core.rotations import quat_between, quat_canonical, quat_normalize, quat_to_rotmat, rotmat_to_quat

__all__ = ["cross_covariance", "horn_rotation_matrix", "horn_rotation", "horn_rotation_eig"]


def cross_covariance(source: torch.Tensor, target: torch.Tensor, weights: torch.Tensor | None = None) -> torch.Tensor:
    """``H = sum_k w_k source_k target_k^T``, ``(..., 3, 3)``.

    Args:
        source, target: ``(..., K, 3)`` corresponding points (broadcastable batch dims).
        weights: ``(K,)`` or ``(..., K)`` non-negative weights, or ``None`` for uniform ``1/K``.
    """
    if source.shape[-1:] != (3,) or source.dim() < 2:
        raise ValueError(f"source must have shape (..., K, 3), got {tuple(source.shape)}")
    if target.shape[-1:] != (3,) or target.dim() < 2 or target.shape[-2] != source.shape[-2]:
        raise ValueError(f"target must have shape (..., K={source.shape[-2]}, 3), got {tuple(target.shape)}")
    K = source.shape[-2]
    if weights is None:
        weights = source.new_full((K,), 1.0 / max(K, 1))
    weights = torch.as_tensor(weights, dtype=source.dtype, device=source.device)
    if weights.dim() < 1 or weights.shape[-1] != K:
        raise ValueError(f"weights must have shape (K={K},) or (..., K), got {tuple(weights.shape)}")
    return (source * weights[..., None]).transpose(-1, -2) @ target


def horn_rotation_matrix(source: torch.Tensor, target: torch.Tensor, weights: torch.Tensor | None = None) -> torch.Tensor:
    """``(..., 3, 3)`` proper rotation ``R`` minimising ``sum_k w_k |target_k - R source_k|^2``.

    Args:
        source, target: ``(..., K, 3)`` corresponding points, pivot already at the origin
            (batch dims broadcast).
        weights: ``(K,)`` or ``(..., K)`` non-negative weights, or ``None`` (uniform).

    Batched SVD of the cross-covariance with the reflection (determinant) correction; see the
    module docstring for the deterministic answers to degenerate (rank 0 or 1) inputs.
    """
    H = cross_covariance(source, target, weights)
    U, S, Vh = torch.linalg.svd(H)
    V = Vh.transpose(-1, -2)
    det = torch.linalg.det(V @ U.transpose(-1, -2))
    fix = torch.ones_like(S)
    fix[..., 2] = torch.where(det < 0, -1.0, 1.0)
    R = V @ (fix[..., None] * U.transpose(-1, -2))
    tol = 1e3 * torch.finfo(H.dtype).eps
    s0 = S[..., 0]
    rank0 = s0 <= torch.finfo(H.dtype).tiny ** 0.5
    rank1 = S[..., 1] <= tol * s0
    R = torch.where(rank1[..., None, None], quat_to_rotmat(quat_between(U[..., :, 0], V[..., :, 0])), R)
    eye = torch.eye(3, dtype=H.dtype, device=H.device)
    return torch.where(rank0[..., None, None], eye, R)


def horn_rotation(source: torch.Tensor, target: torch.Tensor, weights: torch.Tensor | None = None) -> torch.Tensor:
    """``(..., 4)`` unit WXYZ quaternion (``w >= 0``) of :func:`horn_rotation_matrix`.

    The rotation ``q`` minimises ``sum_k w_k |target_k - q source_k|^2``; source, target
    ``(..., K, 3)``; weights ``(K,)``, ``(..., K)`` or ``None`` (uniform).
    """
    return rotmat_to_quat(horn_rotation_matrix(source, target, weights))


def horn_rotation_eig(source: torch.Tensor, target: torch.Tensor, weights: torch.Tensor | None = None) -> torch.Tensor:
    """Horn's quaternion closed form: same rotation as :func:`horn_rotation`, ``(..., 4)`` WXYZ.

    With ``S_ab = H[a, b]`` (``H`` as in :func:`cross_covariance`), ``q`` is the unit
    eigenvector of the largest eigenvalue of the symmetric matrix::

        N = [[Sxx+Syy+Szz, Syz-Szy,      Szx-Sxz,      Sxy-Syx     ],
             [Syz-Szy,     Sxx-Syy-Szz,  Sxy+Syx,      Szx+Sxz     ],
             [Szx-Sxz,     Sxy+Syx,     -Sxx+Syy-Szz,  Syz+Szy     ],
             [Sxy-Syx,     Szx+Sxz,      Syz+Szy,     -Sxx-Syy+Szz ]]

    (``q^T N q = sum_k w_k target_k . (q source_k)``). Returned with ``w >= 0``. Always a
    proper rotation; for degenerate inputs (repeated top eigenvalue) the choice among the
    minimisers is whatever ``torch.linalg.eigh`` returns.
    """
    H = cross_covariance(source, target, weights)
    (sxx, sxy, sxz), (syx, syy, syz), (szx, szy, szz) = (H[..., i, :].unbind(-1) for i in range(3))
    rows = (
        (sxx + syy + szz, syz - szy, szx - sxz, sxy - syx),
        (syz - szy, sxx - syy - szz, sxy + syx, szx + sxz),
        (szx - sxz, sxy + syx, -sxx + syy - szz, syz + szy),
        (sxy - syx, szx + sxz, syz + szy, -sxx - syy + szz),
    )
    N = torch.stack([torch.stack(r, dim=-1) for r in rows], dim=-2)
    _, vecs = torch.linalg.eigh(N)
    return quat_canonical(quat_normalize(vecs[..., :, -1]))
