"""The ``humanml3d`` export format: a folder that text-to-motion training code (MDM, MoMask,
T2M-GPT, MotionGPT, MotionLCM) reads as it reads HumanML3D.

The folder::

    OUT/
      new_joint_vecs/000000.npy   (N, 263) float32: the motion's features (humanml3d_features)
      new_joints/000000.npy       (N, 22, 3) float32: joint positions (m) recovered from them
      texts/000000.txt            captions, one a line: caption#lemma/POS ...#0.0#0.0
      M000000.*                   the mirrored copy (mirror=True)
      Mean.npy, Std.npy           (263,) float32, over every file of new_joint_vecs
      train.txt val.txt test.txt train_val.txt all.txt   IDs, one a line
      index.csv                   each ID: its clip, window (start_s, end_s), rows, mirror, split,
                                  role, locomotion, action, method, database (exported),
                                  locomotion_db and action_db (a spliced clip's sources'
                                  databases, from its run record), retargeted_from, described
                                  (0: its locomotion or its action was not said), and the
                                  clip's CHECK_COLUMNS (empty where the database has none)

Each clip goes onto the SMPL body's 22 joints (``smpl22``: HumanML3D's joint order, metres, its
standard bone lengths) by the analytic retargeting of :mod:`torchsplice.ops.retarget` with the
feet held (:mod:`torchsplice.ops.feet`), unless it is on that body already; then it is
resampled to 20 fps (rotations by slerp, the root linearly: bones keep their lengths), put on the floor, at the origin and facing +Z,
and turned into features as the format does (:mod:`.humanml3d_features`). A clip of fewer than
:data:`MIN_FRAMES` frames at 20 fps is left out (the summary says how many, and how many motions
MDM would drop: :data:`MDM_MIN_ROWS`, :data:`MDM_MAX_ROWS`). ``window`` (seconds) cuts longer
clips into windows of that length, spread evenly over the clip, each with the clip's captions
(a caption of a part, ``#start#end``, in the windows it overlaps, in their time). Captions come from the clips' labels (:mod:`.captions`), splits from the
source clips (:mod:`.splits`). Mean and Std are the format's: the mean of each column over
every row, and the standard deviation of each kind of feature (one value per kind, the mean of
its columns'; :data:`~.humanml3d_features.GROUPS`).

Motions are computed in batches (:func:`_batches`: a motion's last float64 bits depend on its
batch). ``shards=N`` (``--shards N``) writes them as tar files in WebDataset's layout instead of
one file each: ``SPLIT-000000.tar`` ... (about ``N`` in all, each about ``1/N`` of the export:
each split its share, at least one, cut between batches), each member pair ``ID.npy`` and
``ID.txt`` byte for byte ``new_joint_vecs/ID.npy`` and ``texts/ID.txt`` of the folder export;
``Mean.npy``, ``Std.npy``, the split lists and ``index.csv`` beside them as ever. A large export is
then a handful of files, which ``webdataset.WebDataset("OUT/train-{000000..000003}.tar")`` or plain ``tarfile`` reads.

Registered on import; imports no torch until it exports.
"""

from __future__ import annotations

import csv
import io
import json
import math
import tarfile
from dataclasses import replace
from functools import cached_property
from itertools import groupby
from pathlib import Path

from ..core.errors import SpecError, TorchspliceError
from ..core.names import counted, spreadsheet_cell
from .exporters import READ_BATCH, Exporter, ExportOption, ExportResult, register_exporter
from ..data.splits import DEFAULT_RATIOS, SPLITS, parse_ratios, parse_seed, table_splits

__all__ = ["HumanML3DExporter", "MIN_FRAMES", "MDM_MIN_ROWS", "MDM_MAX_ROWS", "INDEX_COLUMNS", "CHECK_COLUMNS"]

MIN_FRAMES = 3
"""Frames (at 20 fps) a clip needs to be exported."""
MDM_MIN_ROWS, MDM_MAX_ROWS = 40, 200
"""MDM's and MoMask's loaders keep motions of 40 to 199 feature rows (and crop to 196);
``window`` cuts longer clips, and is itself at least 40 frames long."""
CHECK_COLUMNS = ("flags", "penetration", "penetration_depth", "corrected_frames", "foot_skate", "jerk", "jerk_action",
                 "foot_slide", "floor", "penetration_locomotion", "penetration_depth_locomotion", "penetration_action",
                 "penetration_depth_action")
"""The source database's columns of what a person would reject (:mod:`torchsplice.job.task`'s ``flags``; a
hand inside the body, its depth in cm and the frames corrected for it; GMD's foot skate ratio; the upper body's
jerk and the action's, m/s^3; the feet's speed in contact, cm/s, and lowest point, cm; the sources' hand
inside and depth), copied into ``index.csv`` (empty where the database has none)."""
INDEX_COLUMNS = ("id", "clip", "start_s", "end_s", "rows", "mirrored", "split", "role", "locomotion", "action",
                 "method", "database", "locomotion_db", "action_db", "retargeted_from", "described", *CHECK_COLUMNS)
EARLIER_INDEX_COLUMNS = (INDEX_COLUMNS[:16], INDEX_COLUMNS[:23])
"""Headers of ``index.csv`` that earlier versions wrote (their exports are still recognised)."""


class HumanML3DExporter(Exporter):
    """Clips as a HumanML3D folder (see the module docstring)."""

    name = "humanml3d"
    suffix = ".npy"
    what = "a HumanML3D folder"
    title = "HumanML3D"
    summary_options = ("split_ratios",)
    options = {
        "captions": ExportOption(None, metavar="FILE",
                                 help="your captions per source clip (JSON: clip name -> list of captions, each "
                                      "'caption#word/POS ...#0.0#0.0' or word/POS words); they compose like the "
                                      "labels' phrases"),
        "mirror": ExportOption(False, help="add each clip's mirrored copy (M + ID), left and right swapped in the "
                                           "motion and its captions (default: off); for the other formats, write the "
                                           "mirror images with `torchsplice mirror` and export that database"),
        "window": ExportOption(None, type=float, metavar="SECONDS",
                               help="cut clips longer than SECONDS into windows of SECONDS spread over the clip, each "
                                    "with the clip's captions (MDM and MoMask keep motions of 40 to 199 frames: "
                                    "windows of at most 9.95 s, at least 2.05 s)"),
        # the index's splits, which every format's export takes (SHARED_OPTIONS); this format writes its own lists
        "split_ratios": ExportOption(DEFAULT_RATIOS, metavar="TRAIN,VAL,TEST",
                                     help="fractions of the source clips in each split of the index (every format) or "
                                          "the HumanML3D lists; a result is in a split when all its sources are "
                                          f"(default: {','.join(f'{r:g}' for r in DEFAULT_RATIOS)})"),
        "split_seed": ExportOption(0, type=int, metavar="N", help="the seed of the split (default: 0)"),
        "paraphrases": ExportOption(3, type=int, metavar="N", help="captions per clip, at most (default: 3)"),
        "shards": ExportOption(None, type=int, metavar="N",
                               help="write the motions as about N tar files in WebDataset's layout (ID.npy, ID.txt; "
                                    "SPLIT-000000.tar ...) instead of one file each"),
    }

    # -- the plan: which files, made from the clip table alone --------------------------------
    @cached_property
    def _plan(self) -> dict:
        from ..store.database import MotionDatabase

        o = self.options
        ratios = parse_ratios(o["split_ratios"])
        window = o["window"]
        if window is not None:
            try:
                window = float(window)
            except (TypeError, ValueError):
                window = -1.0
            if not (window >= (MDM_MIN_ROWS + 1) / 20.0 and math.isfinite(window)):
                raise TorchspliceError(f"{{window}} must be a length in seconds of at least {(MDM_MIN_ROWS + 1) / 20.0:g} "
                                       f"(MDM drops motions of fewer than {MDM_MIN_ROWS} frames), got {o['window']!r}",
                                       options=("window",))
        count = o["paraphrases"]
        if not isinstance(count, int) or isinstance(count, bool) or count < 1:
            raise TorchspliceError(f"{{paraphrases}} must be a whole number of at least 1, got {count!r}",
                                   options=("paraphrases",))
        shards = o["shards"]
        if shards is not None and (not isinstance(shards, int) or isinstance(shards, bool) or shards < 1):
            raise TorchspliceError(f"{{shards}} must be a whole number of at least 1, got {shards!r}", options=("shards",))
        with MotionDatabase.open(self.database) as db:
            table = db.clip_table()
            rows = [db.index(n) for n in self.names]
            plan = _plan_items(table, rows, window, bool(o["mirror"]), ratios, parse_seed(o["split_seed"]),
                               str(self.database), _job_sources(db.attrs.get("run")))
        plan["batches"] = _batches(plan["items"])
        plan["shards"] = _shard_items(plan["batches"], shards) if shards is not None else {}
        return plan

    def layout(self) -> list[str]:
        if self._plan["shards"]:
            return (list(self._plan["shards"]) + ["Mean.npy", "Std.npy"] + [f"{s}.txt" for s in (*SPLITS, "train_val", "all")]
                    + ["index.csv"])
        files = []  # in the order they are computed (_batches)
        for item in (item for batch in self._plan["batches"] for item in batch):
            files += [f"new_joint_vecs/{item['id']}.npy", f"new_joints/{item['id']}.npy", f"texts/{item['id']}.txt"]
        return files + ["Mean.npy", "Std.npy"] + [f"{s}.txt" for s in (*SPLITS, "train_val", "all")] + ["index.csv"]

    @staticmethod
    def earlier_ids(folder: Path) -> list[str] | None:
        """The IDs an earlier torchsplice export wrote to ``folder``, from its ``index.csv`` (whose
        header is :data:`INDEX_COLUMNS`); ``None`` when no torchsplice export wrote there."""
        try:
            with open(Path(folder) / "index.csv", newline="") as f:
                rows = csv.reader(f)
                if tuple(next(rows, ())) not in (INDEX_COLUMNS, *EARLIER_INDEX_COLUMNS):
                    return None
                return [r[0] for r in rows if r]
        except (OSError, UnicodeDecodeError, csv.Error):
            return None

    def owned(self, folder: Path) -> list[Path]:
        ids = self.earlier_ids(folder)
        if ids is None:  # no torchsplice export's record: nothing here is ours to remove
            return []
        files = [folder / sub / f"{i}{suffix}" for i in ids
                 for sub, suffix in (("new_joint_vecs", ".npy"), ("new_joints", ".npy"), ("texts", ".txt"))]
        return [f for f in files if f.is_file()] + sorted(
            f for s in (*SPLITS, "nosplit") for f in folder.glob(f"{s}-[0-9][0-9][0-9][0-9][0-9][0-9].tar"))

    def foreign(self, folder: Path) -> str | None:
        if self.earlier_ids(folder) is not None:
            return None
        found = [n for n in ("new_joint_vecs", "new_joints", "texts", "Mean.npy", "Std.npy", "all.txt", "train.txt",
                             "index.csv") if (folder / n).exists()]
        if not found:
            return None
        return (f"holds a HumanML3D-style dataset ({', '.join(found[:3])}{', ...' if len(found) > 3 else ''}) that no "
                "torchsplice export wrote (its index.csv is not one)")

    # -- checks before any file ---------------------------------------------------------------
    @cached_property
    def _user_captions(self) -> dict:
        from .captions import read_captions

        return read_captions(self.options["captions"]) if self.options["captions"] is not None else {}

    @cached_property
    def _unknown_captions(self) -> list[str]:
        """The ``--captions`` keys that name no clip of the database, nor a source clip of its
        results (said in the summary, not silently unused)."""
        from ..store.database import MotionDatabase

        if not self._user_captions:
            return []
        with MotionDatabase.open(self.database) as db:
            t = db.clip_table()
        known = set(t.names) | {str(v) for col in ("locomotion", "action") if col in t.extra for v in t.extra[col]}
        return [k for k in self._user_captions if k not in known]

    @cached_property
    def _movers(self) -> dict:
        """Per skeleton id: ``None`` (on the SMPL body already, in metres, Y up) or its retargeting
        map onto it (which turns another up axis onto Y)."""
        from ..ops.retarget import retarget_map
        from ..specs import load_spec
        from ..specs.smpl import SMPL22, SMPL22_NAMES, SMPL22_PARENTS, smpl22_skeleton
        from ..store.database import MotionDatabase

        target = smpl22_skeleton()
        target_roles = load_spec(SMPL22).bind(target)
        movers = {}
        with MotionDatabase.open(self.database) as db:
            for k in sorted({item["skeleton"] for item in self._plan["items"]}):
                sk, info = db.skeletons[k], db.skeleton_info(k)
                if tuple(sk.names) == SMPL22_NAMES and tuple(sk.parents) == SMPL22_PARENTS and info.units in ("m", "") \
                        and info.up_axis in ("y", ""):
                    movers[k] = None
                    continue
                try:
                    spec = db.spec(k)
                    movers[k] = retarget_map(sk, spec.bind(sk), target, target_roles,
                                             source_name=f"{self.database}: skeleton {k} ({spec.name})",
                                             target_name=SMPL22)
                except SpecError as exc:
                    raise SpecError(f"{self.database}: skeleton {k} does not map onto the SMPL body: "
                                    f"{' '.join(str(exc).split())}") from None
        return movers

    @cached_property
    def _tables(self) -> dict:
        """Per skeleton id, the phrase tables its clips' labels are looked up in."""
        from ..specs import list_specs, load_spec
        from ..specs.text import spec_phrase_table
        from ..store.database import MotionDatabase

        shipped = [t for t in (spec_phrase_table(load_spec(n)) for n in list_specs()) if t is not None]
        out = {}
        with MotionDatabase.open(self.database) as db:
            for k in sorted({item["skeleton"] for item in self._plan["items"]}):
                try:
                    own = spec_phrase_table(db.spec(k))
                except SpecError:
                    own = None
                out[k] = ([own] if own is not None else []) + [t for t in shipped if t is not own]
        return out

    def check(self) -> None:
        """The plan, the user's captions and every skeleton's map onto the SMPL body, before any file."""
        self._user_captions  # noqa: B018
        self._movers  # noqa: B018
        self._tables  # noqa: B018
        if not self._plan["items"]:
            raise TorchspliceError(f"{self.database}: no clip has {MIN_FRAMES} frames or more at 20 fps to export")

    # -- the files ----------------------------------------------------------------------------
    def items(self):
        import numpy as np

        from .humanml3d_features import FeatureStats

        stats = FeatureStats()
        if self._plan["shards"]:
            for items in self._plan["shards"].values():
                written = {"frames": 0}

                def members(items=items, written=written):  # computed as the tar is written
                    for item, vecs, _, captions in self._clips(items):
                        stats.add(vecs)
                        written["frames"] += int(vecs.shape[0])
                        buf = io.BytesIO()
                        np.save(buf, vecs.numpy().astype(np.float32), allow_pickle=False)
                        yield f"{item['id']}.npy", buf.getvalue()
                        yield f"{item['id']}.txt", "".join(c.line() + "\n" for c in captions).encode("utf-8")

                yield ("tar", written, members())
        else:
            for item, vecs, joints, captions in self._clips([i for batch in self._plan["batches"] for i in batch]):
                stats.add(vecs)
                yield ("npy", item, vecs.numpy().astype(np.float32))
                yield ("npy", None, joints.numpy().astype(np.float32))
                yield ("text", None, "".join(c.line() + "\n" for c in captions))
        rows = self._plan["items"]  # every one written by now (computed in batches, listed in plan order)
        mean, std = stats.result()
        yield ("npy", None, mean.numpy().astype(np.float32))
        yield ("npy", None, std.numpy().astype(np.float32))
        ids = {s: [r["id"] for r in rows if r["split"] == s] for s in SPLITS}
        ids["train_val"] = ids["train"] + ids["val"]
        ids["all"] = [r["id"] for r in rows if r["split"]]  # as HumanML3D's: the splits' union, no other ID
        for s in (*SPLITS, "train_val", "all"):
            yield ("text", None, "".join(i + "\n" for i in ids[s]))
        out = io.StringIO()
        writer = csv.writer(out, lineterminator="\n")
        writer.writerow(INDEX_COLUMNS)
        for r in rows:
            writer.writerow([spreadsheet_cell(r[c]) for c in INDEX_COLUMNS])
        yield ("text", None, out.getvalue())

    def _clips(self, items=None, db=None, batched: bool = True):
        """``(item, features (N, 263), positions (N, 22, 3), captions)`` per planned item (or per
        one of ``items``, planned items), grouped by clip, computed a batch of clips at a time
        (from ``db``, the open database, where given): the export's batches (:func:`_batches`),
        or without ``batched`` up to :data:`READ_BATCH` clips of ``items`` in their order."""
        if db is None:
            from ..store.database import MotionDatabase

            with MotionDatabase.open(self.database) as db:
                yield from self._clips(items, db, batched)
            return

        import torch

        from ..specs.smpl import SMPL22_MIRROR
        from .captions import clip_captions, mirror_caption
        from .humanml3d_features import features_to_positions, pad_clips, positions_to_features

        items = self._plan["items"] if items is None else items
        by_clip: dict[str, list[dict]] = {}
        for item in items:
            by_clip.setdefault(item["clip"], []).append(item)
        runs = [list(g) for _, g in groupby(by_clip, key=lambda n: by_clip[n][0]["batch"] if batched else None)]
        count = self.options["paraphrases"]
        for chunk in (run[b:b + READ_BATCH] for run in runs for b in range(0, len(run), READ_BATCH)):
            positions = self._positions(db.read_many(chunk, dtype=torch.float64))
            pieces, meta = [], []
            for name, p in zip(chunk, positions):
                for item in by_clip[name]:
                    piece = p[item["first"]:item["first"] + item["frames"]]
                    if item["mirrored"]:
                        piece = piece[:, list(SMPL22_MIRROR)] * torch.tensor([-1.0, 1.0, 1.0], dtype=piece.dtype)
                    pieces.append(piece)
                    meta.append(item)
            order = sorted(range(len(pieces)), key=lambda i: pieces[i].shape[0])
            done: dict[int, tuple] = {}
            for s in range(0, len(order), READ_BATCH):  # clips of like lengths padded together
                group = order[s:s + READ_BATCH]
                feats = positions_to_features(pad_clips([pieces[i] for i in group]))
                back = features_to_positions(feats)
                for j, i in enumerate(group):
                    n = pieces[i].shape[0] - 1
                    done[i] = (feats[j, :n], back[j, :n])
            captions_of: dict[str, tuple] = {}
            for i, item in enumerate(meta):
                name = item["clip"]
                if name not in captions_of:
                    captions_of[name] = clip_captions(name, item["role"], item["labels"], self._tables[item["skeleton"]],
                                                      self._user_captions, count, item["locomotion"], item["action"])
                captions, described = captions_of[name]
                start, end = item["first"] / 20.0, (item["first"] + item["frames"] - 1) / 20.0
                inside = [c for c in (c.within(start, end) for c in captions) if c is not None]
                if not inside:  # only captions of other parts of the clip: said whole, and flagged
                    inside, described = [replace(c, start=0.0, end=0.0) for c in captions], False
                if item["mirrored"]:
                    inside = [mirror_caption(c) for c in inside]
                item["described"] = int(described)
                if not bool(torch.isfinite(done[i][0]).all()):
                    raise TorchspliceError(f"{self.database}: clip {name!r}: its features are not finite (NaN or "
                                           "infinity); nothing written")
                yield item, done[i][0], done[i][1], inside

    @property
    def planned_items(self) -> list[dict]:
        """Every motion the export writes, in order: ``id``, ``clip``, ``first``, ``frames`` (at 20
        fps), ``rows``, ``mirrored``, ``split`` ... (the columns of its ``index.csv``)."""
        return self._plan["items"]

    def motions(self, items=None, db=None):
        """``(item, features (N, 263), positions (N, 22, 3), captions)`` of ``items`` (planned
        items; ``None``: all), as the export computes them (to float64's last bits: see :meth:`_clips`)."""
        return self._clips(items, db, batched=False)

    def _positions(self, motions) -> list:
        """Each clip's joint positions ``(T', 22, 3)`` in metres on the SMPL body at 20 fps."""
        import torch

        from ..align.curve import resample_motion
        from ..ops.retarget import retarget_motions
        from .humanml3d_features import FPS

        out: list = [None] * len(motions)
        groups: dict[int, list[int]] = {}
        for i, m in enumerate(motions):
            groups.setdefault(self._plan["skeleton_of"][m.name], []).append(i)
        for k, idx in groups.items():
            chunk = [motions[i] for i in idx]
            if self._movers[k] is not None:
                chunk = retarget_motions(chunk, self._movers[k], True, None)
            # rotations resampled (so that bones keep their lengths), then one FK for the chunk
            chunk = [resample_motion(m.to(torch.float64), FPS) for m in chunk]
            for i, p in zip(idx, _positions_of(chunk)):
                out[i] = p
        return out

    def measure(self, item) -> tuple[int, float | None]:
        kind, meta, array = item
        if kind == "tar":
            return meta["frames"], 20.0
        if meta is None:
            return 0, None
        return int(array.shape[0]), 20.0

    def write(self, item, path: Path) -> None:
        import numpy as np

        kind, _, payload = item
        if kind == "tar":  # members as they are computed; fixed metadata, so equal exports give equal bytes
            with tarfile.open(path, "w", format=tarfile.USTAR_FORMAT) as tar:
                for name, data in payload:
                    info = tarfile.TarInfo(name)
                    info.size, info.mode, info.mtime = len(data), 0o644, 0
                    tar.addfile(info, io.BytesIO(data))
        elif kind == "npy":
            with open(path, "wb") as f:
                np.save(f, payload, allow_pickle=False)
        else:
            Path(path).write_text(payload, encoding="utf-8")

    def summary(self, result: ExportResult) -> str:
        plan = self._plan
        items = plan["items"]
        split = {s: sum(1 for i in items if i["split"] == s) for s in SPLITS}
        unsplit = sum(1 for i in items if i["split"] == "")
        undescribed = sum(1 for i in items if not i.get("described", 1))
        long = sum(1 for i in items if i["rows"] >= MDM_MAX_ROWS)
        short = sum(1 for i in items if i["rows"] < MDM_MIN_ROWS)
        notes = []
        if plan["short"]:
            notes.append(f"{len(plan['short'])} clip{'s' if len(plan['short']) != 1 else ''} under {MIN_FRAMES} frames "
                         "left out")
        unknown = self._unknown_captions
        if unknown:
            notes.append(f"captions for {counted(len(unknown), 'clip')} the database does not hold, not used: "
                         f"{', '.join(repr(k) for k in unknown[:3])}{', ...' if len(unknown) > 3 else ''}")
        if plan.get("not_mirrored"):
            notes.append(f"{counted(len(plan['not_mirrored']), 'clip')} not mirrored again (a mirror image already, "
                         "or its image is exported too)")
        if unsplit:
            notes.append(f"{unsplit} in no split, so in no list, all.txt included (a result is in a split when its "
                         "locomotion and its action both are, and theirs differ; {split_ratios} 1,0,0 puts every "
                         "result in train)")
        if undescribed:
            notes.append(f"{undescribed} whose labels no phrase table describes (captioned 'moves': give them captions)")
        if long:
            notes.append(f"{long} of {MDM_MAX_ROWS} frames or more, which MDM and MoMask drop (cut them with a window)")
        if short:
            notes.append(f"{short} under {MDM_MIN_ROWS} frames, which MDM and MoMask drop")
        return (f"{result.output}: {counted(len(plan['clips']), 'clip')} as HumanML3D, {counted(len(items), 'motion')}"
                f"{' with mirrors' if self.options['mirror'] else ''}, {result.frames} frames at 20 fps; "
                f"train/val/test {split['train']}/{split['val']}/{split['test']}"
                + (f"; {'; '.join(notes)}" if notes else ""))


def _batches(items: list[dict]) -> list[list[dict]]:
    """The batches the export computes its motions in, in order: each split's (train, val, test,
    then none) clips in plan order, :data:`READ_BATCH` clips a batch, with their motions; sets
    ``item["batch"]``. The folder export and every tar of a sharded one compute the same batches."""
    out: list[list[dict]] = []
    for s in (*SPLITS, ""):
        clips: dict[str, list[dict]] = {}
        for i in (i for i in items if (i["split"] or "") == s):
            clips.setdefault(i["clip"], []).append(i)
            i["batch"] = len(out) + (len(clips) - 1) // READ_BATCH
        names = list(clips)
        out += [[i for n in names[b:b + READ_BATCH] for i in clips[n]] for b in range(0, len(names), READ_BATCH)]
    return out


def _shard_items(batches: list[list[dict]], shards: int) -> dict[str, list[dict]]:
    """The tar files of a sharded export (``SPLIT-000000.tar`` ...: each split's batches in
    order, cut between batches into its share of ``shards``, at least one) and the items of each."""
    out: dict[str, list[dict]] = {}
    total = sum(len(b) for b in batches)
    for s in (*SPLITS, "nosplit"):
        mine = [b for b in batches if (b[0]["split"] or "nosplit") == s]
        size = sum(len(b) for b in mine)
        n = min(len(mine), max(1, round(shards * size / total))) if mine else 0
        tars: list[list[dict]] = [[] for _ in range(n)]
        at = 0
        for b in mine:  # a batch goes to the share its middle falls in
            tars[min(n - 1, (2 * at + len(b)) * n // (2 * size))] += b
            at += len(b)
        for k, tar in enumerate(t for t in tars if t):
            out[f"{s}-{k:06d}.tar"] = tar
    return out


def _job_sources(run) -> tuple[str, str]:
    """``(locomotions' database, actions' database)`` of a spliced database, as its run record
    names them (``("", "")`` where it names none)."""
    try:
        record = json.loads(run) if isinstance(run, (str, bytes)) else {}
    except ValueError:
        return "", ""
    if not isinstance(record, dict):
        return "", ""
    db = record.get("database")
    loco = str(db.get("path", "")) if isinstance(db, dict) else str(db or "")
    return loco, str(record.get("actions_db") or loco)


def _positions_of(motions) -> list:
    """Each clip's joint positions ``(T_i, J, 3)``: clips of one skeleton by one forward
    kinematics over their frames concatenated (FK is frame by frame)."""
    import torch

    from ..core.fk import forward_kinematics

    first = motions[0]
    same = all(m.skeleton is first.skeleton or (m.skeleton.parents == first.skeleton.parents and bool(
        torch.equal(m.skeleton.offsets, first.skeleton.offsets))) for m in motions)
    animated = {m.translations is None for m in motions}
    if not same or len(animated) != 1:
        return [m.global_positions() for m in motions]
    trans = None if first.translations is None else torch.cat([m.translations for m in motions])
    pos, _ = forward_kinematics(torch.cat([m.rotations for m in motions]), torch.cat([m.root_translation for m in motions]),
                                first.skeleton.offsets.to(first.rotations), first.skeleton.parents, trans)
    return list(torch.split(pos, [m.num_frames for m in motions]))


def frames_at_20(length: int, fps: float) -> int:
    """Frames a clip of ``length`` frames at ``fps`` has at 20 fps (as the resampling makes them)."""
    return int((length - 1) * 20.0 / fps + 1e-9) + 1


def _plan_items(table, rows: list[int], window: float | None, mirror: bool, ratios, seed: int, database: str,
                sources: tuple[str, str] = ("", "")) -> dict:
    """Every motion the export writes, in order, from the clip table alone: per clip its windows
    (all of it without ``window``), each then its mirrored copy; ids, splits and index columns."""
    clips, short, skeleton_of = [], [], {}
    for r in rows:
        name = table.names[r]
        if frames_at_20(int(table.length[r]), float(table.fps[r])) < MIN_FRAMES:
            short.append(name)
        else:
            clips.append(r)
    infos = {}
    for r in clips:
        info = {"labels": table.labels[r]}
        for col in ("locomotion", "action", "method"):
            info[col] = str(table.extra[col][r]) if col in table.extra else ""
        for col in CHECK_COLUMNS:
            info[col] = _cell(table.extra[col][r] if col in table.extra else "")
        infos[r] = info
    splits = table_splits(table, ratios, seed)  # over the whole database: a selection keeps its clips' splits
    # a clip that is a mirror image (torchsplice mirror's, labelled mirror_of) or whose image is exported
    # too is not mirrored again: its mirrored copy is already there
    exported = {table.names[r] for r in clips}
    imaged = {str(infos[r]["labels"].get("mirror_of")) for r in clips if infos[r]["labels"].get("mirror_of")}
    mirrored_already = {table.names[r] for r in clips if infos[r]["labels"].get("mirror_of")
                        or table.names[r] in imaged or f"{table.names[r]}.mirror" in exported}
    items, n = [], 0
    size = None if window is None else max(MIN_FRAMES, int(round(window * 20.0)))
    for r in clips:
        name, role, info = table.names[r], str(table.role[r]), infos[r]
        skeleton_of[name] = int(table.skeleton[r])
        total = frames_at_20(int(table.length[r]), float(table.fps[r]))
        if size is None or total <= size:
            spans = [(0, total)]
        else:
            count = math.ceil(total / size)
            spans = [(int(round(k * (total - size) / (count - 1))), size) for k in range(count)]
        split = splits[r]
        labels = info["labels"]
        for first, frames in spans:
            base = {"clip": name, "skeleton": int(table.skeleton[r]), "role": role, "labels": labels,
                    "locomotion": info["locomotion"], "action": info["action"], "method": info["method"],
                    "first": first, "frames": frames, "rows": frames - 1, "start_s": f"{first / 20.0:g}",
                    "end_s": f"{(first + frames - 1) / 20.0:g}", "split": split, "database": database,
                    "locomotion_db": sources[0] if role == "spliced" else "",
                    "action_db": sources[1] if role == "spliced" else "",
                    "retargeted_from": labels.get("retargeted_from", labels.get("action.retargeted_from", "")),
                    "described": 1, **{c: info[c] for c in CHECK_COLUMNS}}
            items.append({**base, "id": f"{n:06d}", "mirrored": 0})
            if mirror and name not in mirrored_already:
                items.append({**base, "id": f"M{n:06d}", "mirrored": 1})
            n += 1
    return {"items": items, "clips": [table.names[r] for r in clips], "short": short, "skeleton_of": skeleton_of,
            "not_mirrored": sorted(mirrored_already) if mirror else []}


def _cell(v) -> str:
    """A check column's value in ``index.csv``: floats to 6 digits, empty for NaN and for an int
    column's empty value (-1, a copied source clip's)."""
    import numpy as np  # not at import: ``torchsplice --help`` lists this exporter without NumPy

    if isinstance(v, (float, np.floating)):
        return f"{v:.6g}" if np.isfinite(v) else ""
    return "" if isinstance(v, (int, np.integer)) and v < 0 else str(v)


register_exporter(HumanML3DExporter)
