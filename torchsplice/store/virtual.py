"""Virtual datasets: which files an output's frames are read from (see :mod:`.database`'s layout)."""

from __future__ import annotations

from pathlib import Path

__all__ = ["virtual_source_files"]


def virtual_source_files(output: Path) -> set[Path]:
    """The files whose frames ``output`` reads through virtual datasets (empty for a copy or a
    file that is not there or not readable)."""
    import h5py

    output = Path(output)
    if not output.is_file():
        return set()
    files: set[Path] = set()
    try:
        with h5py.File(output, "r") as f:
            for g in f["skeletons"].values():
                for ds in g.values():
                    if isinstance(ds, h5py.Dataset) and ds.is_virtual:
                        files |= {(output.parent / vs.file_name).resolve() for vs in ds.virtual_sources()
                                  if vs.file_name != "."}
    except (OSError, KeyError, ValueError):
        return set()
    return files
