"""The ``npz`` export format: clips as NumPy ``.npz`` files, one per clip, or every clip in one
packed file (``packed=True``), with training features and their statistics (``features="6d"``).
The layout is :mod:`torchsplice.formats.npz`'s. Registered on import; imports no torch until
it exports."""

from __future__ import annotations

from functools import cached_property
from pathlib import Path

from ..core.names import counted
from .exporters import Exporter, ExportOption, ExportResult, register_exporter
from .npz_features import FEATURE_SETS

__all__ = ["NpzExporter", "FEATURE_SETS"]


class NpzExporter(Exporter):
    """Clips as ``.npz`` (see :mod:`torchsplice.formats.npz` for the layout)."""

    name = "npz"
    suffix = ".npz"
    what = "a NumPy .npz file"
    title = ".npz"
    options = {
        "packed": ExportOption(False, help="one file with every clip concatenated along frames and "
                                           "offsets[i]:offsets[i+1] slicing clip i (clips of one skeleton topology)"),
        "features": ExportOption(None, choices=tuple(FEATURE_SETS),
                                 help="add 6D rotations (Zhou et al. 2019), joint, root and trajectory velocities, and "
                                      "per-dimension mean and std of every array over all exported clips, for "
                                      "normalisation"),
    }

    @cached_property
    def _export(self):
        from .npz import NpzExport

        return NpzExport(self.database, self.clips, features=self.options["features"], skeletons=self.skeletons)

    def select(self) -> list[str]:
        return self._export.names

    @property
    def single_file(self) -> bool:
        return bool(self.options["packed"])

    def check(self) -> None:
        """Clips of one skeleton topology when packed; the statistics computed (and checked
        finite) before any file is made."""
        if self.single_file:
            self._export.check_one_skeleton("pack")
        self._export.statistics  # noqa: B018

    def items(self):
        if self.single_file:
            yield None, None  # the packed file, streamed by write (memory flat in the number of clips)
        else:
            yield from self._export.per_clip()

    def measure(self, item) -> tuple[int, float | None]:
        name, arrays = item
        if name is None:
            return self._export.packed_frames(), None
        return int(arrays["rotations"].shape[0]), float(arrays["fps"])

    def write(self, item, path: Path) -> None:
        from . import npz

        name, arrays = item
        if name is None:
            self._export.write_packed(path)  # staged already
            return
        npz.write_npz(path, arrays, what=f"clip {name!r}", atomic=False)  # staged already

    def summary(self, result: ExportResult) -> str:
        features = self.options["features"]
        n = len(result.names)
        if self.single_file:
            return (f"{result.files[0]}: {counted(n, 'clip')} packed, {result.frames} frames"
                    + (f", features {features} with statistics" if features else ""))
        where = result.files[0] if len(result.files) == 1 else Path(result.output)
        return (f"{where}: {counted(n, 'clip')} as .npz, {result.frames} frames"
                + (f", features {features} with statistics over all of them" if features else ""))


register_exporter(NpzExporter)
