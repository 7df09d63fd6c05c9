"""Finding a spliced database's source clips: its locomotions and actions by name.

A database written by ``splice-all`` names each spliced clip's sources in its ``locomotion``
and ``action`` columns. The clips themselves live in the databases given explicitly
(``--sources``), else in those its ``run`` record names (``database`` and ``actions_db``,
where the files still exist), and in the output itself when the job ran with
``--copy-sources``. ``render``, ``view`` and ``evaluate`` share this lookup.
"""

from __future__ import annotations

import warnings
from pathlib import Path

from ..core.errors import DatabaseError, TorchspliceError
from ..core.motion import Motion
from ..store.database import MotionDatabase
from ..specs import DatasetSpec

__all__ = ["source_databases", "recorded_sources", "SourceClips", "clip_spec", "read_clips"]


def recorded_sources(db: MotionDatabase) -> list[Path]:
    """The input databases named by ``db``'s ``run`` record that still exist (none without one)."""
    run = db.run_record()
    paths = []
    for key in ("database", "actions_db"):
        rec = run.get(key) if isinstance(run, dict) else None
        if isinstance(rec, dict) and rec.get("path") and Path(rec["path"]).is_file():
            if Path(rec["path"]).resolve() != Path(db.path).resolve():
                paths.append(Path(rec["path"]))
    return paths


def source_databases(db: MotionDatabase, sources=None) -> list[MotionDatabase]:
    """Open the source databases of ``db``: ``sources`` (paths) if given, else those its run
    record names (see :func:`recorded_sources`). The caller closes them.

    Raises:
        DatabaseError: a given path that is missing or not a database (one line naming it). A
        recorded one that can no longer be opened (damaged, or replaced by another file since)
        is skipped with a warning: its clips are then missing, as are those of a moved one.
    """
    paths = [Path(p) for p in sources] if sources else recorded_sources(db)
    opened: list[MotionDatabase] = []
    try:
        for p in paths:
            try:
                opened.append(MotionDatabase.open(p))
            except DatabaseError as exc:
                if sources:
                    raise
                warnings.warn(f"{db.path}: its run record's source database is skipped: {exc}", stacklevel=2)
    except BaseException:
        for o in opened:
            o.close()
        raise
    return opened


class SourceClips:
    """Clips by name from the source databases, then from the output itself (read once each)."""

    def __init__(self, dbs: list[MotionDatabase], out_db: MotionDatabase):
        self.dbs = list(dbs) + [out_db]
        self.cache: dict[str, Motion] = {}

    def where(self, name: str) -> MotionDatabase | None:
        """The first database holding a clip named ``name``, or ``None``."""
        return next((d for d in self.dbs if name in d), None)

    def has(self, name: str) -> bool:
        return self.where(name) is not None

    def get(self, name: str) -> Motion:
        """The clip ``name``; a one-line error saying to pass ``--sources`` when no database has it."""
        if name not in self.cache:
            db = self.where(name)
            if db is None:
                raise TorchspliceError(f"source clip {name!r} is in no source database; name them with {{sources}}",
                                       options=("sources",))
            self.cache[name] = db.read(name)
        return self.cache[name]

    def captures(self) -> list[tuple[str, str, dict]]:
        """``(name, role, labels)`` of every clip in the source databases (the output's without any)."""
        out = []
        for db in self.dbs[:-1] or self.dbs:
            out += db.clip_table().captures()
        return out


def clip_spec(db: MotionDatabase, name: str) -> DatasetSpec:
    """The spec of clip ``name``'s skeleton in ``db``: the one stored with it, else one detected
    (:meth:`MotionDatabase.spec <torchsplice.store.database.MotionDatabase.spec>`)."""
    return db.spec(db.clip_info(name)["skeleton"])


def read_clips(database, names, sources=None) -> tuple[list[Motion], DatasetSpec]:
    """Clips by name from ``database``, or, for names it lacks (a spliced clip's locomotion or
    action), from its source databases (:func:`source_databases`); and the first clip's spec.

    Raises:
        DatabaseError: a name no database holds (one line, with similar names in ``database``).
    """
    with MotionDatabase.open(database) as db:
        srcs = source_databases(db, sources)
        try:
            lookup = SourceClips(srcs, db)
            clips = []
            for name in names:
                home = db if name in db else lookup.where(name)
                if home is None:
                    db.index(name)  # the database's own error, with similar names
                clips.append(home.read(name))
            first = db if names[0] in db else lookup.where(names[0])
            return clips, clip_spec(first, names[0])
        finally:
            for s in srcs:
                s.close()
