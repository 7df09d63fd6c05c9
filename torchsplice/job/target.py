"""``splice-all --target TARGET``: every clip brought onto one skeleton before the job splices.

:func:`onto_target` retargets the job's databases onto ``config.target`` (a database's skeleton,
a BVH rig or ``smpl22``: :func:`torchsplice.retarget.resolve_target`) with
:func:`~torchsplice.retarget.retarget_clips`, into databases beside the output
(``OUT.target-locomotions.h5``, and ``OUT.target-actions.h5`` for ``--actions-db``), and
returns the configuration that reads them. They are the output's sources (its run record names
them, and ``render``, ``view`` and ``evaluate`` find the source clips there), and they are made
once: a rerun or a resumed job reuses them while their input, target (its file too) and settings
are the same (a ``.json`` beside each says what it was made from, written once the database is
complete).
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

from ..core.version import __version__
from ..store.atomic import atomic_path
from .config import JobConfig

__all__ = ["onto_target", "target_paths"]


def target_paths(config: JobConfig, folder: Path | None = None) -> tuple[Path, Path | None]:
    """Where :func:`onto_target` writes the locomotions' and the actions' database (``folder``:
    instead of beside the output)."""
    base = Path(folder) if folder is not None else config.output.parent
    stem = config.output.name
    return (base / f"{stem}.target-locomotions.h5",
            base / f"{stem}.target-actions.h5" if config.actions_db is not None else None)


def _stat(path) -> dict:
    st = Path(path).stat()
    return {"path": str(Path(path).resolve()), "size": st.st_size, "mtime_ns": st.st_mtime_ns}


def _made_for(source: Path, target, config: JobConfig) -> dict:
    """What a target database was made from: its source and target files (path, size, time),
    the target's name and the settings."""
    return {"source": _stat(source), "target": str(config.target),
            "target_file": _stat(target.path) if target.path is not None else None,
            "fix_feet": config.fix_feet, "tool": f"torchsplice {__version__}"}


def onto_target(config: JobConfig, folder: Path | None = None, progress=None) -> JobConfig:
    """``config`` reading its clips retargeted onto ``config.target`` (see the module docstring);
    ``config`` itself when it has no target."""
    if config.target is None:
        return config
    from ..retarget import resolve_target, retarget_clips  # loaded by jobs with a target only

    target = resolve_target(config.target)  # once, for both databases
    out_l, out_a = target_paths(config, folder)
    for source, out in ((config.database, out_l), (config.actions_db, out_a)):
        if source is None:
            continue
        record = Path(f"{out}.json")
        want = _made_for(source, target, config)
        try:
            ready = out.exists() and json.loads(record.read_text()) == want
        except (OSError, ValueError):
            ready = False
        if not ready:
            record.unlink(missing_ok=True)
            retarget_clips(source, to=target, out=out, fix_feet=config.fix_feet, overwrite=True,
                           command=f"splice-all --target {config.target}", progress=progress)
            with atomic_path(record) as tmp:
                Path(tmp).write_text(json.dumps(want))
    return replace(config, database=out_l, actions_db=out_a)
