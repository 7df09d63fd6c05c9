"""The job's source clips: read once per process, prepared once per locomotion group.

Clips are keyed ``"L:ROW"`` (the locomotion database) and ``"A:ROW"`` (the action database;
``"L:ROW"`` as well when both are one file). A *group* is a locomotion skeleton and frame rate;
its bank (:class:`~torchsplice.cpu.bank.ClipBank`) holds the group's locomotions and every
action and reference of the same topology, resampled to the group's rate, with forward
kinematics and grid features computed once per clip. Workers build the same bank from the same
clips, so every engine splices from identical arrays.
"""

from __future__ import annotations

from pathlib import Path

from ..core.motion import Motion
from ..io.database import MotionDatabase
from ..splice.clips import resample_motion

__all__ = ["Sources", "clip_key", "split_key"]


def clip_key(tag: str, row: int, same_db: bool) -> str:
    """The key of row ``row`` of database ``tag`` (``"L"`` or ``"A"``)."""
    return f"{'L' if same_db else tag}:{int(row)}"


def split_key(key: str) -> tuple[str, int]:
    tag, row = key.split(":")
    return tag, int(row)


class Sources:
    """Clips of one job, read on demand (a database at a time) and kept; banks per group.

    Made from database paths (opened here, also in a worker process) or, for workers without
    the files (a Ray cluster), from the clips themselves (:meth:`from_motions`).
    """

    def __init__(self, database: Path | None = None, actions_db: Path | None = None, dbs: dict | None = None):
        self.paths = {"L": database, "A": actions_db or database}
        self.dbs: dict = dict(dbs or {})
        self.motions: dict[str, Motion] = {}
        self.banks: dict = {}

    @classmethod
    def from_motions(cls, motions: dict[str, Motion]) -> "Sources":
        out = cls()
        out.motions = dict(motions)
        return out

    def db(self, tag: str) -> MotionDatabase:
        if tag not in self.dbs:
            other = self.dbs.get("A" if tag == "L" else "L")
            same = other is not None and Path(self.paths[tag]).resolve() == Path(self.paths["A" if tag == "L" else "L"]).resolve()
            self.dbs[tag] = other if same else MotionDatabase.open(self.paths[tag])
        return self.dbs[tag]

    def close(self) -> None:
        for db in {id(d): d for d in self.dbs.values()}.values():
            db.close()
        self.dbs.clear()

    def load(self, keys) -> None:
        """Read the clips not read yet, a database at a time."""
        for tag in ("L", "A"):
            rows = sorted({split_key(k)[1] for k in keys if split_key(k)[0] == tag and k not in self.motions})
            if rows:
                for row, m in zip(rows, self.db(tag).read_many(rows)):
                    self.motions[f"{tag}:{row}"] = m

    def motion(self, key: str) -> Motion:
        if key not in self.motions:
            self.load([key])
        return self.motions[key]

    def group_motions(self, keys) -> dict[str, Motion]:
        """The clips of ``keys`` (for shipping to a worker without the files)."""
        self.load(keys)
        return {k: self.motions[k] for k in keys}

    def bank(self, group_id: int, keys: list[str], fps: float, roles, landmarks) -> tuple:
        """``(bank, index)`` of a group, built on first use: ``index`` maps a clip key to its bank row."""
        if group_id not in self.banks:
            from ..cpu.bank import ClipBank

            self.load(keys)
            motions = [self.motions[k] for k in keys]
            bank = ClipBank.from_motions([resample_motion(m, fps) for m in motions], motions[0].skeleton, roles, landmarks)
            self.banks[group_id] = (bank, {k: i for i, k in enumerate(keys)})
        return self.banks[group_id]

    def standing_tables(self, group_id: int, roles, skeleton, fps: float):
        """The group's tables for standing actions (:func:`~torchsplice.splice.standing.standing_tables`), made once."""
        key = ("standing", group_id)
        if key not in self.banks:
            from ..splice.standing import standing_tables

            self.banks[key] = standing_tables(roles, skeleton, fps)
        return self.banks[key]
