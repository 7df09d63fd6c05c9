"""The built-in methods, registered in :mod:`torchsplice.splice.registry`: ``splice`` (Heck,
Kovar & Gleicher 2006), ``naive`` (per-bone replacement of the upper body) and ``cpmc``
(differencing against a plain-locomotion reference, Al-Ghreimil & Hahn 2003).

Each is one :class:`~torchsplice.splice.registry.Method`: its torch function (padded pair
tensors, any device) and its standing-action variant; all three also run in the compiled CPU
splicer (:mod:`torchsplice.cpu`). The torch modules are imported when a method first runs, so
that listing the methods loads no torch.
"""

from __future__ import annotations

from .registry import Method, MethodInput, MethodOutput, register_method

__all__ = ["SPLICE", "NAIVE", "CPMC"]


def _run_splice(inp: MethodInput) -> MethodOutput:
    """Heck et al. 2006 on a batch (see :func:`torchsplice.splice.heck.splice_tensors`)."""
    import torch

    from .heck import splice_tensors

    out = splice_tensors(inp.loco, inp.act, inp.roles, inp.skeleton, inp.options.align, inp.fps,
                         posture=inp.options.posture, twist=inp.options.twist)
    al = out.alignment
    B = inp.loco.lengths.shape[0]
    q = out.posture_rotation
    return MethodOutput(
        clips=out.clips, times=al.curve + al.crop[:, None], cost=al.cost, crop=al.crop,
        paths=[al.cells[b, : int(al.path_length[b])] for b in range(B)],
        pelvis_correction=torch.rad2deg(out.pelvis_correction).to(torch.float64),
        posture_deg=torch.rad2deg(2 * torch.atan2(q[:, 1:].norm(dim=-1), q[:, 0].abs())),
    )


def _run_naive(inp: MethodInput) -> MethodOutput:
    """Naive DOF replacement (see :func:`torchsplice.splice.methods.naive_tensors`)."""
    from .methods import naive_tensors

    clips, times = naive_tensors(inp.loco, inp.act, inp.roles, inp.skeleton)
    return MethodOutput(clips=clips, times=times)


def _run_cpmc(inp: MethodInput) -> MethodOutput:
    """CPMC differencing (see :func:`torchsplice.splice.methods.cpmc_tensors`)."""
    from .methods import cpmc_tensors

    clips, al, _ = cpmc_tensors(inp.loco, inp.act, inp.ref, inp.roles, inp.skeleton, inp.options.align, inp.fps)
    B = inp.loco.lengths.shape[0]
    return MethodOutput(clips=clips, times=al.curve + al.crop[:, None], cost=al.cost, crop=al.crop,
                        paths=[al.cells[b, : int(al.path_length[b])] for b in range(B)])


def _standing(name: str):
    """The standing-action variant of built-in method ``name`` (see :mod:`torchsplice.splice.standing`)."""
    def run(inp: MethodInput, timing: str, acting):
        from .standing import standing_tensors

        return standing_tensors(inp.loco, inp.act, inp.roles, inp.skeleton, inp.fps, name, timing, acting)

    run.__qualname__ = f"standing_{name}"
    return run


SPLICE = register_method(Method(
    "splice", "Heck, Kovar & Gleicher 2006: timewarp, spatial alignment, posture transfer", _run_splice,
    compiled=True, standing=_standing("splice"), diagnostics=("cost", "crop", "posture")))
NAIVE = register_method(Method(
    "naive", "per-bone replacement of the upper body, frame by frame, no timewarp (game engines' layer masks)",
    _run_naive, compiled=True, standing=_standing("naive")))
CPMC = register_method(Method(
    "cpmc", "differencing against a plain-locomotion reference of the action's performer (additive layers)",
    _run_cpmc, needs_reference=True, compiled=True, standing=_standing("cpmc"), diagnostics=("cost", "crop")))
