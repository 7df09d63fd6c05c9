"""The job's source clips: read once per process, prepared once per job.

Clips are keyed ``"L:ROW"`` (the locomotion database) and ``"A:ROW"`` (the action database;
``"L:ROW"`` as well when both are one file); ``"R{K}A:ROW"`` (or ``"R{K}L:ROW"``) is that action
retargeted onto the locomotion database's skeleton ``K`` (:func:`retargeted_key`), made once
per process from the stored clip (:mod:`torchsplice.ops.retarget`, the feet fixed unless
``fix_feet`` is off) and kept like any other clip; its labels say what it was retargeted from. A *group* is a locomotion skeleton and frame rate;
its bank (the clips as a backend prepares them, :meth:`~torchsplice.splice.backends.Backend.prepare`:
for the compiled splicer a :class:`~torchsplice.cpu.bank.ClipBank`) holds the group's locomotions and every
action and reference of the same topology, resampled to the group's rate, with forward
kinematics and grid features computed once per clip. Groups of one topology, spec and rate
share one bank, holding all their clips (:meth:`Sources.share_banks`): a clip's arrays do not
depend on which bank holds it.

The driver builds the banks while it plans and writes them into the job's work folder
(:meth:`Sources.save_banks`); local workers map those files (copy-on-write) instead of
reading and preparing the clips again, so the clips sit in memory once, whatever the number
of workers. Every engine splices from identical arrays.
"""

from __future__ import annotations

import shutil
from dataclasses import replace
from pathlib import Path

from ..core.motion import Motion
from ..ops.body import body_of
from ..ops.hands import arms_of
from ..ops.plausibility import figure_joints
from ..store.database import MotionDatabase
from ..splice.clips import resample_motion
from ..splice.standing import standing_tables

__all__ = ["Sources", "clip_key", "split_key", "retargeted_key", "retargeted_parts"]


def clip_key(tag: str, row: int, same_db: bool) -> str:
    """The key of row ``row`` of database ``tag`` (``"L"`` or ``"A"``)."""
    return f"{'L' if same_db else tag}:{int(row)}"


def split_key(key: str) -> tuple[str, int]:
    tag, row = key.split(":")
    return tag, int(row)


def retargeted_key(key: str, skeleton: int) -> str:
    """The key of clip ``key`` (``"A:ROW"``/``"L:ROW"``) retargeted onto locomotion skeleton ``skeleton``."""
    return f"R{int(skeleton)}{key}"


def retargeted_parts(key: str) -> tuple[int, str] | None:
    """``(skeleton, source key)`` of a retargeted clip's key, ``None`` for any other key."""
    if not key.startswith("R"):
        return None
    tag, row = split_key(key)
    return int(tag[1:-1]), f"{tag[-1]}:{row}"


class Sources:
    """Clips of one job, read on demand (a database at a time) and kept; banks per group.

    Made from database paths (opened here, also in a worker process) or, for workers without
    the files (a Ray cluster), from the clips themselves (:meth:`from_motions`).
    """

    def __init__(self, database: Path | None = None, actions_db: Path | None = None, dbs: dict | None = None,
                 bank_dir: Path | None = None, bank_tag: str = "", fix_feet: bool = True):
        self.paths = {"L": database, "A": actions_db or database}
        self.dbs: dict = dict(dbs or {})
        self.motions: dict[str, Motion] = {}
        self.banks: dict = {}
        self.backends: dict = {}  # bank -> the backend that prepared it
        self.shared: dict[int, tuple[int, list[str]]] = {}  # group -> (its bank, the bank's clips)
        self.bank_dir = bank_dir  # where the driver's banks are, as files (None: built here)
        self.bank_tag = bank_tag  # what the banks there must have been made for (the plan's digest)
        self.fix_feet = fix_feet
        self.retargeting: dict = {}  # (source tag, source skeleton, target skeleton) -> its Retargeter
        self.targets: dict = {}  # target skeleton -> its RetargetTarget
        self.models: dict = {}  # (what, group) -> its body model, arms or figure joints (body_model)

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
        """Read the clips not read yet, a database at a time (and retarget those asked for so)."""
        keys = list(keys)
        made = [k for k in keys if k not in self.motions and retargeted_parts(k) is not None]
        wanted = set(keys) | {retargeted_parts(k)[1] for k in made}
        for tag in ("L", "A"):
            rows = sorted({split_key(k)[1] for k in wanted if split_key(k)[0] == tag and k not in self.motions})
            if rows:
                for row, m in zip(rows, self.db(tag).read_many(rows)):
                    self.motions[f"{tag}:{row}"] = m
        batches: dict[tuple, list[str]] = {}  # retargeted together: one batch per source skeleton and target
        for key in made:
            target, source = retargeted_parts(key)
            tag, row = split_key(source)
            batches.setdefault((tag, int(self.db(tag).clip_table().skeleton[row]), target), []).append(key)
        for (tag, skeleton, target), keys_ in batches.items():
            done = self.retargeting_for(tag, skeleton, target)([self.motions[retargeted_parts(k)[1]] for k in keys_])
            self.motions.update(zip(keys_, done))

    def retargeting_for(self, tag: str, skeleton: int, target: int):
        """The :class:`~torchsplice.retarget.clips.Retargeter` of clips of database ``tag``'s
        skeleton ``skeleton`` onto the locomotion database's skeleton ``target``, made once
        (raises the map's one-line error for a skeleton that is not a humanoid)."""
        key = (tag, skeleton, target)
        if key not in self.retargeting:
            # loaded by jobs that retarget, not by every worker (as in .plan)
            from ..retarget.clips import Retargeter, source_label
            from ..retarget.targets import database_target

            if target not in self.targets:  # measured once per target skeleton, on the open database
                self.targets[target] = database_target(self.db("L"), self.paths["L"], target)
            db = self.db(tag)
            spec = db.spec(skeleton)
            self.retargeting[key] = Retargeter(db.skeletons[skeleton], spec, source_label(self.paths[tag], skeleton, spec.name),
                                               self.targets[target], self.fix_feet,
                                               what=f"{self.paths[tag]}: skeleton {skeleton} ({spec.name})")
        return self.retargeting[key]

    def motion(self, key: str) -> Motion:
        if key not in self.motions:
            self.load([key])
        return self.motions[key]

    def group_motions(self, keys) -> dict[str, Motion]:
        """The clips of ``keys`` (for shipping to a worker without the files)."""
        self.load(keys)
        return {k: self.motions[k] for k in keys}

    def share_banks(self, groups) -> None:
        """Let the locomotion ``groups`` (:class:`~torchsplice.job.plan.Group`) of one topology,
        spec and frame rate share one bank, holding the clips of all of them."""
        skeletons = self.db("L").skeletons
        members: dict[tuple, list[int]] = {}
        for n, g in enumerate(groups):
            sk = skeletons[g.skeleton]
            members.setdefault((g.fps, g.spec, tuple(sk.names), tuple(sk.parents)), []).append(n)
        self.shared = {}
        for ns in members.values():
            keys = list(dict.fromkeys(k for n in ns for k in groups[n].clips))
            for n in ns:
                self.shared[n] = (ns[0], keys)

    def bank(self, group_id: int, keys: list[str], fps: float, roles, options, backend) -> tuple:
        """``(bank, index)`` of a group: its clips as ``backend`` prepares them (with ``options``),
        built (or mapped from :attr:`bank_dir`) on first use; ``index`` maps a clip key to its row."""
        bank_id, keys = self.shared.get(group_id, (group_id, keys))
        if bank_id not in self.banks:
            folder = self._bank_folder(bank_id)
            if folder is not None and self._bank_made_here(folder):
                bank = backend.load(folder)
            else:
                self.load(keys)
                motions = [self.motions[k] for k in keys]
                bank = backend.prepare([resample_motion(m, fps) for m in motions], motions[0].skeleton, roles, options)
            self.banks[bank_id] = (bank, {k: i for i, k in enumerate(keys)})
            self.backends[bank_id] = backend
        return self.banks[bank_id]

    def _bank_folder(self, bank_id: int) -> Path | None:
        return None if self.bank_dir is None else Path(self.bank_dir) / f"bank-{bank_id}"

    def _bank_made_here(self, folder: Path) -> bool:
        try:
            return (folder / "made_for").read_text() == self.bank_tag
        except OSError:
            return False

    def save_banks(self, folder: Path, tag: str) -> None:
        """Write the banks built so far into ``folder`` (:meth:`ClipBank.save`, once each, marked
        as made for ``tag``: the plan's digest), and map them from there from now on, so that
        this process holds them once too."""
        self.bank_dir, self.bank_tag = Path(folder), tag
        for bank_id, (bank, index) in list(self.banks.items()):
            if not isinstance(bank_id, int):
                continue
            target = self._bank_folder(bank_id)
            if not self._bank_made_here(target):
                shutil.rmtree(target, ignore_errors=True)  # another plan's
                self.backends[bank_id].save(bank, target)
                (target / "made_for").write_text(tag)
            self.banks[bank_id] = (self.backends[bank_id].load(target), index)

    def unsaved_bank_bytes(self, folder: Path) -> int:
        """Bytes :meth:`save_banks` would write into ``folder`` now (banks not there yet)."""
        return sum(self.backends[k].prepared_bytes(b) for k, (b, _) in self.banks.items()
                   if isinstance(k, int) and not (Path(folder) / f"bank-{k}" / "made_for").exists())

    def release_banks(self) -> None:
        """Let go of the banks saved in :attr:`bank_dir` (the mapped pages they hold): a later
        :meth:`bank` maps them again from there. Banks held only in memory are kept."""
        for bank_id in [k for k in self.banks if isinstance(k, int)]:
            folder = self._bank_folder(bank_id)
            if folder is not None and self._bank_made_here(folder):
                del self.banks[bank_id]

    def release_clips(self, keep=()) -> None:
        """Forget the clips read so far (but ``keep``, copied: clips read together share one
        buffer, which a kept clip would hold whole): the banks hold what splicing needs."""
        copy = lambda t: None if t is None else t.clone()  # noqa: E731
        self.motions = {k: replace(m, rotations=copy(m.rotations), root_translation=copy(m.root_translation),
                                   translations=copy(m.translations))
                        for k, m in self.motions.items() if k in set(keep)}

    def body_model(self, what: str, group_id: int, skeleton, roles):
        """The group's ``"body"`` (:func:`~torchsplice.ops.body.body_of`), ``"arms"``
        (:func:`~torchsplice.ops.hands.arms_of`) or ``"figures"`` joints
        (:func:`~torchsplice.ops.plausibility.figure_joints`) of ``skeleton`` (bound ``roles``),
        made once: each finds the skeleton's canonical joints, milliseconds that every task
        of a job of short standing pairs would spend again (8% of its time)."""
        key = (what, group_id)
        if key not in self.models:
            if what == "body":
                self.models[key] = body_of(skeleton, roles)
            elif what == "arms":
                self.models[key] = arms_of(skeleton, roles, self.body_model("body", group_id, skeleton, roles))
            else:
                self.models[key] = figure_joints(skeleton, roles)
        return self.models[key]

    def standing_tables(self, group_id: int, roles, skeleton, fps: float):
        """The group's tables for standing actions (:func:`~torchsplice.splice.standing.standing_tables`), made once."""
        key = ("standing", group_id)
        if key not in self.banks:
            self.banks[key] = standing_tables(roles, skeleton, fps)
        return self.banks[key]
