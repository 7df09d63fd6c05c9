"""The time alignment of one pair as a picture (Heck et al. 2006, Figure 3).

Top: the lower-body frame distance grid as a heat map (dark = similar; rows are frames of
the locomotion, columns frames of the action at the locomotion's frame rate), the optimal DP
path and the fitted alignment curve over it, and the phase crop as a dashed line. Bottom: the
per-frame angle of the spatial-alignment rotation ``q_A`` applied to the pelvis.
"""

from __future__ import annotations

from pathlib import Path

import torch

from ..core.errors import TorchspliceError
from ..core.motion import Motion
from ..store.atomic import atomic_path
from ..specs import DatasetSpec
from ..splice import SpliceOptions, splice
from ..splice.clips import clips_to_tensors, resample_motion
from ..splice.heck import alignment_grid

__all__ = ["alignment_data", "plot_alignment"]


def alignment_data(locomotion: Motion, action: Motion, spec: DatasetSpec, options: SpliceOptions | None = None) -> dict:
    """What :func:`plot_alignment` draws, as tensors.

    Returns a dict: ``grid`` ``(Tl, Ta)`` float64 frame distances over the whole action (at the
    locomotion's rate), ``crop`` (int), ``path`` ``(P, 2)`` (locomotion frame, action frame,
    uncropped), ``curve`` ``(T,)`` action frame per result frame (uncropped, at the
    locomotion's rate), ``pelvis_deg`` ``(T,)``, ``cost`` and ``result`` (the SpliceResult).
    """
    options = options or SpliceOptions(force=True)
    result = splice(locomotion, action, spec, options=options)
    roles = spec.bind(locomotion.skeleton)
    act = resample_motion(action, locomotion.fps)
    L = clips_to_tensors([locomotion], locomotion.skeleton, dtype=torch.float64)
    A = clips_to_tensors([act], locomotion.skeleton, dtype=torch.float64)
    grid = alignment_grid(L, A, roles, options.align)[0]
    scale = locomotion.fps / action.fps  # result.curve is in the action's own frames
    crop_l = int(round(result.crop * scale))
    path = result.path.clone()
    path[:, 1] += crop_l
    return {"grid": grid, "crop": crop_l, "path": path, "curve": result.curve * scale,
            "pelvis_deg": result.pelvis_correction, "cost": result.cost, "result": result}


def plot_alignment(locomotion: Motion, action: Motion, spec: DatasetSpec, output, options: SpliceOptions | None = None,
                   dpi: int = 110) -> Path:
    """Write the alignment picture of one pair to ``output`` (PNG, PDF or SVG), atomically."""
    import matplotlib  # here, not at import: the Agg backend is chosen before pyplot loads

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    output = Path(output)
    if output.suffix.lower() not in (".png", ".pdf", ".svg"):
        raise TorchspliceError(f"{output}: unsupported picture type {output.suffix or '(none)'!r}; write .png, .pdf or .svg")
    d = alignment_data(locomotion, action, spec, options)
    grid = d["grid"].cpu().numpy()
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(6.4, 8.0), gridspec_kw={"height_ratios": [3, 1]})
    try:
        im = top.imshow(grid, origin="lower", aspect="auto", cmap="magma",
                        vmax=float(torch.quantile(d["grid"].flatten(), 0.95)))
        fig.colorbar(im, ax=top, label=f"frame distance ({spec.units if spec.units != 'unknown' else 'units'}²)")
        path = d["path"].numpy()
        t = torch.arange(len(d["curve"])).numpy()
        top.plot(path[:, 1], path[:, 0], color="cyan", lw=1.2, label="optimal DP path")
        top.plot(d["curve"].numpy(), t, color="lime", lw=1.0, ls="--", label="alignment curve λ(t)")
        if d["crop"]:
            top.axvline(d["crop"], color="white", ls=":", lw=1.0, label=f"phase crop ({d['crop']} frames)")
        top.set_xlabel(f"action frame: {action.name}")
        top.set_ylabel(f"locomotion frame: {locomotion.name}")
        top.set_title(f"lower-body distance grid, mean cost {d['cost']:.3g}")
        top.legend(loc="upper left", fontsize=8)
        bottom.plot(t, d["pelvis_deg"].numpy(), color="tab:blue")
        bottom.set_xlabel("result frame")
        bottom.set_ylabel("pelvis correction (deg)")
        bottom.grid(alpha=0.3)
        fig.tight_layout()
        with atomic_path(output) as tmp:
            fig.savefig(tmp, dpi=dpi, format=output.suffix.lstrip(".") or "png")
    finally:
        plt.close(fig)
    return output
