"""HumanML3D's motion representation: 263 features a frame from the SMPL body's 22 joint positions,
and the positions back from the features.

Written from the format's description (EricGuo5513/HumanML3D, ``motion_representation.ipynb``);
no code of it is copied.

Conventions (the format's): joint positions ``(T, 22, 3)`` in metres, Y up, in SMPL's and
HumanML3D's joint order (:data:`torchsplice.specs.smpl.SMPL22_NAMES`), the character's left on
+X and facing +Z at its first frame once :func:`normalize_positions` has run; quaternions WXYZ.
A clip of ``T`` frames gives ``T - 1`` feature rows:

=========  ====  ============================================================================
columns    size  what
=========  ====  ============================================================================
0          1     the root's yaw velocity: ``asin`` of the Y part of ``r[t+1] r[t]^-1`` (so the
                 half-angle; the short quaternion of that turn), ``r`` the root's heading
                 rotation (its facing onto +Z; the identity at the first frame)
1:3        2     the root's X/Z velocity, in the heading frame of frame ``t+1``
3          1     the root's height
4:67       63    joints 1..21 relative to the root, X/Z about the root, in the heading frame
67:193     126   joints 1..21's rotations (6D: the rotation matrix's first two columns), each
                 the swing from the raw offset direction of its bone (:data:`RAW_OFFSETS`) in
                 its parent's frame
193:259    66    the 22 joints' velocities (``p[t+1] - p[t]``) in the heading frame of frame ``t``
259:263    4     foot contacts: left ankle, left foot, right ankle, right foot (squared
                 displacement to the next frame below :data:`FOOT_THRESHOLD` m^2)
=========  ====  ============================================================================

The heading: ``forward = up x across``, ``across`` the sum of two left-right vectors, smoothed
by a Gaussian of 20 frames (``mode='nearest'``) for the features; the reference adds the hips'
left-to-right vector to the shoulders' right-to-left one there (its joint indices read in the
other order; the shoulders, wider, decide), and both left-to-right where it turns a clip to face
+Z. Both are kept as the format has them, so that features agree with the reference's.
"""

from __future__ import annotations

import torch

from ..core.rotations import quat_between, quat_conj, quat_mul, quat_to_6d

__all__ = ["FEATURES", "JOINTS", "FOOT_THRESHOLD", "RAW_OFFSETS", "CHAINS", "FPS", "GROUPS", "normalize_positions",
           "positions_to_features", "features_to_positions", "gaussian_smooth", "FeatureStats",
           "pad_clips"]

FPS = 20.0
"""The format's frame rate."""

GROUPS = ((0, 1), (1, 3), (3, 4), (4, 67), (67, 193), (193, 259), (259, 263))
"""The feature columns by kind (yaw velocity, root velocity, root height, joint positions, joint
rotations, joint velocities, contacts): ``Std.npy`` holds one value per kind."""

JOINTS = 22
FEATURES = 263
FOOT_THRESHOLD = 0.002
"""Squared per-frame displacement (m^2) below which a foot joint is in contact."""

RAW_OFFSETS = ((0, 0, 0), (1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, -1, 0), (0, 1, 0), (0, -1, 0), (0, -1, 0),
               (0, 1, 0), (0, 0, 1), (0, 0, 1), (0, 1, 0), (1, 0, 0), (-1, 0, 0), (0, 0, 1), (0, -1, 0), (0, -1, 0),
               (0, -1, 0), (0, -1, 0), (0, -1, 0), (0, -1, 0))
"""Each joint's bone direction at rest, from its parent (the format's, for the rotation features)."""

CHAINS = ((0, 2, 5, 8, 11), (0, 1, 4, 7, 10), (0, 3, 6, 9, 12, 15), (9, 14, 17, 19, 21), (9, 13, 16, 18, 20))
"""The kinematic chains: right leg, left leg, spine to head, right arm, left arm."""

_L_HIP, _R_HIP, _L_SHOULDER, _R_SHOULDER = 1, 2, 16, 17
_FEET = (7, 10, 8, 11)  # left ankle, left foot, right ankle, right foot


def _check(positions: torch.Tensor) -> None:
    if positions.dim() < 3 or positions.shape[-2:] != (JOINTS, 3):
        raise ValueError(f"positions must be (..., T, {JOINTS}, 3), got {tuple(positions.shape)}")
    if positions.shape[-3] < 2:
        raise ValueError(f"a clip needs at least 2 frames, got {positions.shape[-3]}")


def gaussian_smooth(x: torch.Tensor, sigma: float, dim: int = 0) -> torch.Tensor:
    """``x`` smoothed along ``dim`` by a Gaussian of ``sigma`` samples, cut at 4 sigma, the ends
    padded with their own values (``mode='nearest'``)."""
    radius = int(4.0 * sigma + 0.5)
    t = torch.arange(-radius, radius + 1, dtype=x.dtype, device=x.device)
    kernel = torch.exp(-0.5 * (t / sigma) ** 2)
    kernel = kernel / kernel.sum()
    moved = x.movedim(dim, -1)
    shape = moved.shape
    flat = moved.reshape(-1, 1, shape[-1])
    idx = torch.arange(-radius, shape[-1] + radius, device=x.device).clamp(0, shape[-1] - 1)
    out = torch.nn.functional.conv1d(flat[..., idx], kernel.flip(0)[None, None])
    return out.reshape(shape).movedim(-1, dim)


def _yaw_apply(q: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
    """Rotate ``(..., 3)`` vectors by turns about +Y given as quaternions ``(w, 0, y, 0)``
    (broadcastable ``(..., 4)``): ``quat_apply`` for the heading, without its general cross products."""
    w, y = q[..., 0:1], q[..., 2:3]
    c, s = w * w - y * y, 2.0 * w * y  # cos and sin of the turn
    x, z = v[..., 0:1], v[..., 2:3]
    return torch.cat((c * x + s * z, v[..., 1:2], c * z - s * x), dim=-1)


def _cross(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """``a x b`` for broadcastable ``(..., 3)`` vectors."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return torch.stack((a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0), dim=-1)


def _cross_up(v: torch.Tensor) -> torch.Tensor:
    """``up x v`` with up = +Y: ``(v_z, 0, -v_x)`` (what ``torch.linalg.cross`` gives, without
    broadcasting the constant)."""
    return torch.stack((v[..., 2], torch.zeros_like(v[..., 0]), -v[..., 0]), dim=-1)


def _across(p: torch.Tensor, l_hip: int, r_hip: int) -> torch.Tensor:
    """The sum of the hips' ``l_hip -> r_hip`` vector and the shoulders' right-to-left one, unit."""
    across = (p[..., r_hip, :] - p[..., l_hip, :]) + (p[..., _R_SHOULDER, :] - p[..., _L_SHOULDER, :])
    return across / across.norm(dim=-1, keepdim=True)


def _turn_to_z(forward: torch.Tensor) -> torch.Tensor:
    """``(..., 4)`` the turn about +Y taking horizontal ``forward`` ``(..., 3)`` onto +Z (the short
    way; a forward along -Z turns about Y too, where the smallest rotation has no unique axis)."""
    half = -0.5 * torch.atan2(forward[..., 0], forward[..., 2])
    zero = torch.zeros_like(half)
    return torch.stack((torch.cos(half), zero, torch.sin(half), zero), dim=-1)


def _heading(positions: torch.Tensor, smooth: bool) -> torch.Tensor:
    """``(..., T, 4)`` the root's heading rotation (taking its forward onto +Z), as the format's
    features have it (see the module docstring)."""
    across = _across(positions, _R_HIP, _L_HIP)  # the reference's order: left minus right hip
    forward = _cross_up(across)
    if smooth:  # its Y is 0: only X and Z need smoothing
        xz = gaussian_smooth(forward[..., ::2], 20.0, dim=-2)
        forward = torch.stack((xz[..., 0], torch.zeros_like(xz[..., 0]), xz[..., 1]), dim=-1)
    return _turn_to_z(forward)


def normalize_positions(positions: torch.Tensor) -> torch.Tensor:
    """``(..., T, 22, 3)`` each clip on the floor (its lowest joint at Y = 0), its first frame's
    root above the origin, and turned about Y to face +Z at its first frame (the format's rules)."""
    _check(positions)
    p = positions.clone()
    p[..., 1] -= p[..., 1].amin(dim=(-2, -1))[..., None, None]
    start = p[..., :1, :1, :].clone()
    start[..., 1] = 0.0
    p = p - start
    across = _across(p[..., 0, :, :], _L_HIP, _R_HIP)
    forward = _cross_up(across)
    turn = _turn_to_z(forward)
    return _yaw_apply(turn[..., None, None, :], p)


def _joint_rotations(positions: torch.Tensor, root: torch.Tensor) -> torch.Tensor:
    """``(..., T, 22, 4)`` each joint's rotation in its parent's frame: the swing taking its raw
    offset direction onto its bone (chain by chain, from the heading ``root``)."""
    out = torch.zeros(positions.shape[:-1] + (4,), dtype=positions.dtype)
    out[..., 0] = 1.0
    out[..., 0, :] = root
    raw = torch.tensor(RAW_OFFSETS, dtype=positions.dtype)
    for chain in CHAINS:
        R = root
        for a, b in zip(chain, chain[1:]):
            v = positions[..., b, :] - positions[..., a, :]
            v = v / v.norm(dim=-1, keepdim=True).clamp_min(1e-12)
            # the smallest rotation from the raw direction u onto v (never antipodal for a body's bones;
            # quat_between's fallback is kept for that case)
            u = raw[b]
            d = (v * u).sum(-1, keepdim=True)
            swing = torch.cat((1.0 + d, _cross(u, v)), dim=-1)
            if bool((1.0 + d < 1e-6).any()):
                swing = torch.where(1.0 + d < 1e-6, quat_between(u.expand_as(v), v), swing)
            swing = swing / swing.norm(dim=-1, keepdim=True)
            out[..., b, :] = quat_mul(quat_conj(R), swing)
            R = swing  # R (R^-1 swing): the bone's global rotation is its swing
    return out


def positions_to_features(positions: torch.Tensor, normalize: bool = True, dtype=torch.float64) -> torch.Tensor:
    """``(..., T - 1, 263)`` features of clips' joint positions ``(..., T, 22, 3)`` (see the module
    docstring); ``normalize`` first puts each on the floor, at the origin, facing +Z
    (:func:`normalize_positions`), as the format's folders hold them. Computed in ``dtype``
    (float64 by default, as the export does: in float32, root-relative positions of a clip far
    from the origin lose bone lengths to 4e-5 m).

    Clips of other lengths go in one batch padded at the end with copies of their last frame
    (:func:`pad_clips`): the smoothing repeats the last frame there anyway, so each clip's
    first ``T_i - 1`` rows are its own features exactly."""
    _check(positions)
    p = normalize_positions(positions.to(dtype)) if normalize else positions.to(dtype)
    T = p.shape[-3]
    # contacts
    step = ((p[..., 1:, _FEET, :] - p[..., :-1, _FEET, :]) ** 2).sum(-1)
    feet = (step < FOOT_THRESHOLD).to(dtype)
    # the heading, smoothed (the first frame's is the identity: the clip faces +Z there), and
    # the rotations from it
    r_rot = _heading(p, smooth=True)
    r_rot[..., 0, :] = torch.tensor((1.0, 0.0, 0.0, 0.0), dtype=p.dtype)
    quats = _joint_rotations(p, r_rot)
    root_vel = _yaw_apply(r_rot[..., 1:, :], p[..., 1:, 0, :] - p[..., :-1, 0, :])
    r_vel = quat_mul(r_rot[..., 1:, :], quat_conj(r_rot[..., :-1, :]))
    # the turn's own (short) quaternion: where the heading crosses 180 degrees its quaternion changes
    # cover, and the raw product's Y part would flip sign (the reference keeps that flip: one frame of
    # a clip turning past 180 degrees then recovers turning the wrong way; here it recovers right)
    r_vel = torch.where(r_vel[..., :1] < 0, -r_vel, r_vel)
    yaw = torch.asin(r_vel[..., 2:3].clamp(-1.0, 1.0))
    # joints relative to the root, in the heading frame
    local = p.clone()
    local[..., 0] -= p[..., 0:1, 0]
    local[..., 2] -= p[..., 0:1, 2]
    local = _yaw_apply(r_rot[..., None, :], local)
    lead = p.shape[:-3]
    six = quat_to_6d(quats[..., 1:, :]).reshape(lead + (T, -1))
    vel = _yaw_apply(r_rot[..., :-1, None, :], p[..., 1:, :, :] - p[..., :-1, :, :])
    return torch.cat([yaw, root_vel[..., [0, 2]], p[..., :-1, 0, 1:2], local[..., :-1, 1:, :].reshape(lead + (T - 1, -1)),
                      six[..., :-1, :], vel.reshape(lead + (T - 1, -1)), feet], dim=-1)


def pad_clips(clips) -> torch.Tensor:
    """``(B, T_max, ...)`` clips ``(T_i, ...)`` stacked, each padded at its end with copies of its
    last frame (how :func:`positions_to_features` takes clips of other lengths in one batch)."""
    clips = list(clips)
    longest = max(c.shape[0] for c in clips)
    out = torch.empty((len(clips), longest) + tuple(clips[0].shape[1:]), dtype=clips[0].dtype)
    for i, c in enumerate(clips):
        out[i, :c.shape[0]] = c
        out[i, c.shape[0]:] = c[-1]
    return out


def features_to_positions(features: torch.Tensor) -> torch.Tensor:
    """``(..., N, 22, 3)`` joint positions from features ``(..., N, 263)``, by the root's
    integrated heading and velocity and the root-relative joints (the format's ``recover_from_ric``)."""
    if features.shape[-1] != FEATURES:
        raise ValueError(f"features must have {FEATURES} columns, got {features.shape[-1]}")
    f = features
    yaw = torch.zeros_like(f[..., 0])
    yaw[..., 1:] = f[..., :-1, 0]
    yaw = torch.cumsum(yaw, dim=-1)
    r_rot = torch.zeros(f.shape[:-1] + (4,), dtype=f.dtype, device=f.device)
    r_rot[..., 0] = torch.cos(yaw)
    r_rot[..., 2] = torch.sin(yaw)
    step = torch.zeros(f.shape[:-1] + (3,), dtype=f.dtype, device=f.device)
    step[..., 1:, 0] = f[..., :-1, 1]
    step[..., 1:, 2] = f[..., :-1, 2]
    root = torch.cumsum(_yaw_apply(quat_conj(r_rot), step), dim=-2)
    root[..., 1] = f[..., 3]
    joints = f[..., 4:4 + (JOINTS - 1) * 3].reshape(f.shape[:-1] + (JOINTS - 1, 3))
    joints = _yaw_apply(quat_conj(r_rot)[..., None, :], joints)
    joints[..., 0] += root[..., None, 0]
    joints[..., 2] += root[..., None, 2]
    return torch.cat([root[..., None, :], joints], dim=-2)


class FeatureStats:
    """``Mean.npy`` and ``Std.npy`` of feature arrays, as the format computes them: the mean and
    the (population) standard deviation of every column over every row of every clip, then each
    kind's standard deviations replaced by their mean (:data:`GROUPS`; a kind whose deviation is
    0 gets 1, so that normalizing divides by no zero). Streamed: :meth:`add` one
    clip's ``(N, 263)`` at a time, memory flat in the number of clips (sums in float64)."""

    def __init__(self):
        self.n = 0
        self.total = torch.zeros(FEATURES, dtype=torch.float64)
        self.squares = torch.zeros(FEATURES, dtype=torch.float64)

    def add(self, features: torch.Tensor) -> None:
        f = torch.as_tensor(features, dtype=torch.float64)
        if f.dim() != 2 or f.shape[1] != FEATURES:
            raise ValueError(f"features must be (N, {FEATURES}), got {tuple(f.shape)}")
        self.n += f.shape[0]
        self.total += f.sum(0)
        self.squares += (f * f).sum(0)

    def result(self) -> tuple[torch.Tensor, torch.Tensor]:
        """``(mean, std)``, each ``(263,)`` float64."""
        if self.n == 0:
            raise ValueError("no features were added")
        mean = self.total / self.n
        std = (self.squares / self.n - mean * mean).clamp_min(0).sqrt()
        for a, b in GROUPS:
            std[a:b] = std[a:b].mean()
        # a kind that never varies (every foot always in contact, in a handful of clips) would
        # divide by zero in training: 1 there, the one departure from the format's computation
        return mean, torch.where(std > 1e-8, std, torch.ones_like(std))
