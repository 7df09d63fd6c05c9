"""The assembly of :mod:`torchsplice.cpu.assemble` in torch, for reads of an alignment store on
a GPU (``device=``): every result frame at once, on the device.

The same formulas (split of the fractional frame, slerp along the shorter arc, linear
translations, a standing loop's inertialized seam, the locomotion's secondary spine motion),
in the bank's float64, written as float32: equal to the compiled kernels' frames to float32's
rounding (tested on the CPU), not bit for bit (the motion store's bits are the compiled
kernels'). Inputs as :class:`~torchsplice.store.assembly.Assembly` gathers them: the bank
``rot (N, J, 4)``, ``trans (N, J, 3)`` (WXYZ, local; a torch tensor on the device), and per
result frame its rows in the bank.
"""

from __future__ import annotations

import numpy as np
import torch

from ..core.rotations import axis_angle_to_quat, quat_conj, quat_mul, quat_normalize, quat_slerp, quat_to_axis_angle

__all__ = ["split_times", "timewarp_frames", "standing_frames"]


def split_times(x: torch.Tensor, n: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """``(i0, i1, w)`` to sample clips of ``n`` frames at fractional frames ``x`` (clamped to
    ``[0, n - 1]``), as :func:`torchsplice.cpu.curve.split_time`."""
    top = (n - 1).to(x.dtype)
    x = torch.minimum(torch.clamp(x, min=0.0), top)
    i0 = torch.floor(x)
    return i0.long(), torch.minimum(i0 + 1, top).long(), x - i0


def _slerp(p: torch.Tensor, q: torch.Tensor, w: torch.Tensor) -> torch.Tensor:
    """Slerp of ``(..., 4)`` along the shorter arc, ``p`` itself where ``w`` is 0 (as the kernels)."""
    return torch.where(w[..., None] == 0, p, quat_slerp(p, q, w))


def timewarp_frames(rot, trans, lrow, arow0, arow1, w, prot, upper, pelvis) -> tuple[torch.Tensor, torch.Tensor]:
    """Frames of timewarp clips: ``lrow (M,)`` the locomotion's bank rows, ``arow0``/``arow1``
    ``(M,)`` the action's rows either side of its frame and ``w (M,)`` the weight, ``prot (M, 4)``
    the pelvis's rotation; ``upper (J,)`` bool, ``pelvis`` its joint. ``(rotations (M, J, 4),
    translations (M, J, 3))`` float32."""
    orot, otrans = rot[lrow].clone(), trans[lrow].clone()
    a0, a1 = rot[arow0][:, upper], rot[arow1][:, upper]
    ww = w[:, None].expand(-1, a0.shape[1])
    orot[:, upper] = _slerp(a0, a1, ww)
    t0, t1 = trans[arow0][:, upper], trans[arow1][:, upper]
    otrans[:, upper] = torch.where(ww[..., None] == 0, t0, t0 + ww[..., None] * (t1 - t0))
    orot[:, pelvis] = prot.to(rot.dtype)
    otrans[:, pelvis] = trans[lrow, pelvis]
    return orot.float(), otrans.float()


def _times(t, Tl, Ta, timing, window, loop_s, loop_e, blend):
    """``(time, fade source, phase)`` per result frame, as :func:`torchsplice.cpu.assemble.standing_times`."""
    one = torch.ones_like(t)
    fit = t * (Ta - 1.0) / torch.clamp(Tl - 1.0, min=1.0)
    windowed = torch.minimum(window + t, Ta - 1.0)
    hold = torch.minimum(t, Ta - 1.0)
    period = torch.clamp(loop_e - loop_s, min=1.0)
    after = t - loop_e
    u = after - torch.floor(after / period) * period
    looped = torch.where(t >= loop_e, loop_s + u, t)
    phase = torch.where((t >= loop_e) & (u < blend), torch.clamp(u / blend, 0.0, 1.0), one)
    x = torch.where(timing == 2, fit, torch.where(Tl <= Ta, windowed, torch.where(timing == 1, hold, looped)))
    phase = torch.where((timing == 0) & (Tl > Ta), phase, one)
    return x, torch.where(phase < 1.0, loop_e, x), phase


def standing_frames(
    rot,
    trans,
    clip,
    t,
    lstart,
    Tl,
    astart,
    Ta,
    method,
    timing,
    window,
    loop_s,
    loop_e,
    acting,
    upper,
    spine,
    arms,
    blend_s,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Frames of standing clips, as :func:`torchsplice.cpu.assemble.standing_rows`: per result
    frame ``clip (M,)`` (which of the ``B`` clips) and ``t`` (its frame); per clip (``(B,)``) the
    locomotion's first bank row ``lstart`` and frames ``Tl``, the action's ``astart``, ``Ta``,
    ``method``, ``timing``, ``window``, loop points, ``acting (B, 2)``; the skeleton's tables."""
    dev, f64 = rot.device, rot.dtype
    J = rot.shape[1]
    B = lstart.shape[0]
    blend = torch.clamp(torch.minimum(torch.full_like(Ta, blend_s), Ta // 3), min=1)
    # the locomotion's mean posture of each spine joint, per clip
    S = spine.shape[0]
    mean = torch.zeros((B, S, 4), dtype=f64, device=dev)
    if S:
        owner = torch.repeat_interleave(torch.arange(B, device=dev), Tl)
        rows = (
            lstart[owner]
            + torch.arange(int(Tl.sum()), device=dev)
            - torch.repeat_interleave(torch.cumsum(Tl, 0) - Tl, Tl)
        )
        q = rot[rows][:, spine]  # (R, S, 4)
        q0 = rot[lstart][:, spine][owner]
        sign = torch.where((q * q0).sum(-1, keepdim=True) < 0, -1.0, 1.0).to(f64)
        mean.index_add_(0, owner, sign * q)
        mean = quat_normalize(mean)
    c = clip
    tf = t.to(f64)
    x, source, phase = _times(
        tf,
        Tl[c].to(f64),
        Ta[c].to(f64),
        timing[c],
        window[c].to(f64),
        loop_s[c].to(f64),
        loop_e[c].to(f64),
        blend[c].to(f64),
    )
    lrow = lstart[c] + t
    base = astart[c]

    def sample(at):
        i0, i1, w = split_times(at, Ta[c])
        return base + i0, base + i1, w

    a0, a1, w = sample(x)
    q = _slerp(rot[a0], rot[a1], w[:, None].expand(-1, J))
    tr = trans[a0] + w[:, None, None] * (trans[a1] - trans[a0])
    fading = phase < 1.0
    if bool(fading.any()):
        sph = phase[:, None]
        u = sph * blend[c].to(f64)[:, None]
        f = 1 - sph * sph * (3 - 2 * sph)
        g = u * (1 - sph) ** 2

        def at(x_):
            r0, r1, ww = sample(x_)
            return _slerp(rot[r0], rot[r1], ww[:, None].expand(-1, J)), trans[r0] + ww[:, None, None] * (
                trans[r1] - trans[r0]
            )

        qb, lb = at(source)
        qbp, lbp = at(source - 1)
        qs, ls_ = at(loop_s[c].to(f64))
        qn, ln = at(loop_s[c].to(f64) + 1)
        r = quat_to_axis_angle(quat_mul(qb, quat_conj(qs)))
        v1 = quat_to_axis_angle(quat_mul(qb, quat_conj(qbp)))
        v2 = quat_to_axis_angle(quat_mul(qn, quat_conj(qs)))
        faded = quat_normalize(quat_mul(axis_angle_to_quat(r * f[..., None] + (v1 - v2) * g[..., None]), q))
        q = torch.where(fading[:, None, None], faded, q)
        offset = (lb - ls_) * f[..., None] + ((lb - lbp) - (ln - ls_)) * g[..., None]
        tr = torch.where((fading & (method[c] == 1))[:, None, None], tr + offset, tr)
    lq, ltr = rot[lrow], trans[lrow]
    m = method[c][:, None]
    cp = quat_normalize(quat_mul(lq, quat_mul(quat_conj(rot[base]), q)))
    spine_k = torch.full((J,), -1, dtype=torch.long, device=dev)
    spine_k[spine] = torch.arange(S, device=dev)
    sp = q
    if S:
        mk = mean[c][:, torch.clamp(spine_k, min=0)]  # (M, J, 4)
        sp = torch.where((spine_k >= 0)[None, :, None], quat_normalize(quat_mul(q, quat_mul(quat_conj(mk), lq))), q)
    out_q = torch.where((m == 2)[..., None], cp, torch.where((m == 0)[..., None], sp, q))
    out_t = torch.where((m == 1)[..., None], tr, ltr)
    idle = torch.zeros((B, J), dtype=torch.bool, device=dev)
    for a in range(2):
        idle |= (~acting[:, a])[:, None] & arms[a][None, :]
    keep = (~upper)[None, :] | ((m == 0) & idle[c])
    out_q = torch.where(keep[..., None], lq, out_q)
    out_t = torch.where(keep[..., None], ltr, out_t)
    return out_q.float(), out_t.float()


def as_tensor(a, device, dtype=None) -> torch.Tensor:
    """A numpy array as a tensor on ``device``."""
    return torch.as_tensor(np.ascontiguousarray(a), device=device, dtype=dtype)
