"""Retargeting clips of a database onto another skeleton: the ``torchsplice retarget`` command
as one function (:func:`retarget_clips`), and the targets it takes (:func:`resolve_target`).

The math on clips is :mod:`torchsplice.ops.retarget` (rest poses aligned per bone, the
trajectory scaled by leg length) and :mod:`torchsplice.ops.feet` (the feet held where the
source's stand); this package reads the database, names the target, and writes the result:

    from torchsplice.retarget import retarget_clips
    report = retarget_clips("cmu.h5", to="bandai.h5:0", out="cmu_on_bandai.h5")
    report = retarget_clips("bandai.h5", ["dataset-2_wave-right-hand_normal_001"], to="smpl22", out="wave_smpl.h5")

A target is a skeleton of a database (``other.h5``, or ``other.h5:K`` when it holds several), a
BVH file (its skeleton; its frames, where it has some, say how high its feet stand), or the
built-in SMPL body (``smpl22``, :mod:`torchsplice.specs.smpl`).

The names below are imported on first use, so that the defaults (:mod:`.defaults`) are read
without torch.
"""

from typing import TYPE_CHECKING

from ..core.lazy import lazy_names

if TYPE_CHECKING:  # pragma: no cover
    from .clips import RetargetReport, retarget_clips
    from .targets import BUILTIN_TARGETS, RetargetTarget, resolve_target

__all__ = ["retarget_clips", "RetargetReport", "resolve_target", "RetargetTarget", "BUILTIN_TARGETS"]

__getattr__, __dir__ = lazy_names(__name__, {
    "retarget_clips": ".clips", "RetargetReport": ".clips",
    "resolve_target": ".targets", "RetargetTarget": ".targets", "BUILTIN_TARGETS": ".targets",
})
