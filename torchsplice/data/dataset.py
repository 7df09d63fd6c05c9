"""Training data from a motion database: a ``torch.utils.data.Dataset`` and its collate function.

:class:`MotionDataset` serves the clips of any torchsplice motion database (an input database
or one written by the splice job), whole or cut into fixed-length windows, as dicts of
tensors; :func:`collate_motion` pads such items into a batch. A training-data loop::

    from torch.utils.data import DataLoader
    from torchsplice.data import MotionDataset, collate_motion

    ds = MotionDataset("spliced.h5", where={"role": "spliced"}, window=60,
                       features=("rotations", "positions"))
    loader = DataLoader(ds, batch_size=32, shuffle=True, collate_fn=collate_motion, num_workers=2)
    for batch in loader:
        x = batch["rotations"]            # (B, 60, J, 4) local WXYZ quaternions
        p = batch["positions"]            # (B, 60, J, 3) world positions, file units
        loss = model_loss(x, p, batch["mask"])   # mask (B, 60): True on real frames

Conventions, as everywhere in torchsplice: quaternions are unit quaternions in **WXYZ** order;
rotations are local (joint frame to parent frame) unless the feature's name says
``global``; positions and translations are in the database's file units (its ``units``
attribute) with the database's up axis (Y for every shipped dataset). ``T`` is the number of
frames of an item (the window length, or the clip's length), ``J`` the skeleton's joints.

Features (``features=``):

=====================  ===============  ===================================================
name                   shape            meaning
=====================  ===============  ===================================================
``rotations``          ``(T, J, 4)``    local joint rotations, WXYZ, as stored
``root_translation``   ``(T, 3)``       world position of joint 0, as stored (on datasets whose
                                        BVH root stands still, e.g. Bandai Namco, it is zero:
                                        read ``trajectory``)
``trajectory``         ``(T, 3)``       world position of the joint carrying the character's
                                        trajectory: the dataset spec's ``root`` role (Bandai
                                        Namco ``Hips``; joint 0 for most datasets)
``translations``       ``(T, J, 3)``    local joint translations in the parent's frame:
                                        the animated ones where the skeleton animates
                                        them, the rest offsets elsewhere; row 0 is the
                                        root translation (as ``Motion.local_translations``)
``positions``          ``(T, J, 3)``    world joint positions, by batched forward kinematics
``global_rotations``   ``(T, J, 4)``    world joint rotations (joint frame to world), WXYZ
``velocities``         ``(T, J, 3)``    ``(positions[t] - positions[t-1]) * fps``; a clip's
                                        first frame copies its second (zero for a one-frame
                                        clip). A window that does not start a clip uses
                                        the frame before it, so a window's velocities are
                                        exactly the slice of its clip's velocities.
``rotations_6d``       ``(T, J, 6)``    local rotations in the 6D representation of Zhou et
                                        al. 2019: the first two columns of each rotation
                                        matrix (:func:`~torchsplice.core.rotations.quat_to_6d`;
                                        ``rotation_6d_to_rotmat`` inverts it)
``trajectory_velocity`` ``(T, 3)``      velocity of ``trajectory``, as ``velocities``
``root_velocity``      ``(T, 3)``       velocity of ``root_translation``, as ``velocities``
``labels``             a dict           the clip's labels (not per frame: ``collate_motion``
                                        gives a list of dicts)
any per-frame column   ``(T,)``         e.g. ``action_frame`` of a spliced database
                                        (stored as float32, NaN where not given)
=====================  ===============  ===================================================

Every feature but ``labels`` comes as ``dtype`` (float32 by default).

Normalisation statistics: :meth:`MotionDataset.statistics` gives, per feature, the mean and
standard deviation of every dimension over every frame of the selected clips, computed in
batches (``(x - mean) / std`` then has zero mean and unit variance over them; see the method
for dimensions that never change). ``torchsplice export --format npz --features 6d`` stores the
same numbers beside the exported features.

Workers: the dataset holds no open HDF5 file when it is made or pickled; each process opens
the file itself on its first read (and a process forked from one that had it open opens its
own), so it works with ``DataLoader(num_workers=N)`` under fork, spawn and forkserver.
Items take their clip metadata from numpy arrays, so forked workers do not copy it page by page.

Speed: an item reads just its frames (one slice per stored array). ``DataLoader`` fetches a
batch through :meth:`MotionDataset.__getitems__`, which runs forward kinematics once for the
whole batch. Random windows cost mostly the decompression of the HDF5 chunks they touch
(1024 gzip-compressed frames by default); a database written with smaller chunks or without
compression, or ``preload=True``, is several times faster to sample at random.
"""

from __future__ import annotations

import operator
import os
from pathlib import Path
from typing import Any, Iterable, Mapping, NamedTuple, Sequence

import numpy as np
import torch
from torch.utils.data import Dataset

from ..core.ranges import lengths_to_starts, ranges_to_rows
from ..core.skeleton import Skeleton
from ..store import MotionDatabase
from .collate import collate_motion  # noqa: F401 (its home before data.collate)
from .errors import DatasetError
from .features import BUILTIN_FEATURES, NEEDS_FK, NOT_PER_FRAME, VELOCITY, derive_features, trajectory_joint
from .where import selection_mask
from .sampler import SkeletonBatchSampler

__all__ = ["MotionDataset", "collate_motion", "DatasetError", "FeatureStatistics", "BUILTIN_FEATURES", "ITEM_KEYS"]

ITEM_KEYS = ("name", "length", "fps", "index", "start", "skeleton")
"""The metadata keys of every item, besides its features."""


def _window_and_stride(window: int | None, stride: int | None) -> tuple[int | None, int | None]:
    """``(window, stride)`` checked: a stride needs a window and defaults to it; both at least 1."""
    if window is None:
        if stride is not None:
            raise ValueError("stride needs a window")
        return None, None
    window = operator.index(window)
    stride = window if stride is None else operator.index(stride)
    if window < 1 or stride < 1:
        raise ValueError(f"window and stride must be at least 1, got window={window}, stride={stride}")
    return window, stride


class FeatureStatistics(NamedTuple):
    """Normalisation statistics of one feature (float64 tensors of the feature's per-frame shape).

    Attributes:
        mean: per-dimension mean over every frame, e.g. ``(J, 6)`` for ``rotations_6d``.
        std: per-dimension population standard deviation (``ddof=0``); zero where a dimension
            never changes (a joint that does not move, a fixed root).
        frames: how many frames they were computed over.
    """

    mean: torch.Tensor
    std: torch.Tensor
    frames: int


class MotionDataset(Dataset):
    """Clips (or fixed-length windows of clips) of a motion database as dicts of tensors.

    Args:
        path: the database file (any torchsplice motion database).
        clips: clips to use: names, shell patterns (``"walk_*"``) or row numbers; ``None`` for
            every clip. A name that is not in the database, or a pattern that matches nothing,
            is an error.
        where: metadata filters, all of which a clip must pass, e.g.
            ``{"role": "spliced", "labels.style": ["elderly", "proud"], "cost": lambda c: c < 5}``.
            Keys: the base columns (``name``, ``source``, ``role``, ``skeleton``, ``start``,
            ``length``, ``fps``, ``labels`` — the labels as a dict), ``labels.KEY`` (the label's
            string, ``None`` where a clip lacks it) and the database's extra per-clip columns
            (``str``, ``float`` — NaN where unset — or ``int``). Values: a value to equal, a
            list/tuple/set of accepted values, or a callable on the value returning truth.
            An unknown key raises :class:`DatasetError`.
        window: ``None`` for one item per clip (variable length); ``W`` for items of exactly
            ``W`` frames, windows ``start = 0, S, 2S, ...`` with ``start + W <= T`` over every
            clip (``floor((T - W) / S) + 1`` per clip); clips shorter than ``W`` give none and
            are counted in :attr:`num_too_short`.
        stride: ``S``, frames between window starts; defaults to ``window``. Only with ``window``.
        features: names of the per-frame tensors of each item, see the module docstring
            (``rotations``, ``root_translation``, ``trajectory``, ``translations``, ``positions``,
            ``global_rotations``, ``velocities``, ``rotations_6d``, ``trajectory_velocity``,
            ``root_velocity``, ``labels`` — a dict, not a tensor — or any per-frame column of
            the database).
        dtype: floating dtype of every feature tensor.
        preload: read every selected clip and compute its features once, here; items are then
            slices of memory (fast for datasets that fit in RAM; no file access afterwards).
        select: selectors of the job's and the exports' selection language (one string or a
            list, all of which a clip must pass; see :mod:`torchsplice.store.select`), e.g.
            ``["role:spliced", "method:splice", "label:action.style=elderly"]``.
        split: ``"train"``, ``"val"`` or ``"test"``: only the clips of that split, split by
            source clips (:mod:`torchsplice.data.splits`: ``split_ratios`` of the locomotions and
            actions, seeded by ``split_seed``; a result is in a split when both its sources are),
            so that no action or locomotion of the test split is trained on. Sources are split
            over the whole database, so a clip's split is the same whatever else is selected,
            and the same as the HumanML3D export gives it with the same ratios and seed.
        assemble_on: a device (``"cuda"``, ``"cpu"``) on which :meth:`collate` makes each
            batch's features at once: a batch fetch (``__getitems__``, what ``DataLoader`` calls)
            then gives the items' metadata only, and ``DataLoader(ds, batch_size=B,
            collate_fn=ds.collate)`` reads the batch's frames, or an alignment store's parts
            (a few bytes per frame), assembles them there with torch
            (:meth:`~torchsplice.store.database.MotionDatabase.assembled_on`) and derives the
            features there. On a GPU the collate runs in the loading process, so use
            ``num_workers=0`` (a worker is refused in one line). ``ds[i]`` is unchanged.

    Items (``ds[i]``): a dict with each feature as a ``(T, ...)`` tensor and ``name`` (str),
    ``length`` (int, ``T``), ``fps`` (float), ``index`` (the clip's row in the database),
    ``start`` (the window's first frame within the clip, 0 for whole clips) and ``skeleton``
    (int, the database skeleton the clip is on). Clips of several skeletons may be mixed: batch
    them with :meth:`batch_sampler` (each batch of one skeleton topology), or filter with
    ``where={"skeleton": k}``.

    Attributes:
        path, features, window, stride, dtype, preload: as given (features as a tuple).
        indices: ``(C,)`` int64 database rows of the selected clips, in row order.
        names: the selected clips' names, in the same order.
        table: the selected clips' metadata, column -> ``(C,)`` numpy array (as
            :meth:`MotionDatabase.table`, labels as JSON strings).
        skeletons: every skeleton of the database (``item["skeleton"]`` indexes it).
        num_clips: number of selected clips; num_too_short: how many of them are shorter than
            ``window`` (and so give no item; when all are, the dataset is refused with a
            :class:`DatasetError`); too_short: their names.
    """

    def __init__(self, path, clips: Iterable[str | int] | None = None, where: Mapping[str, Any] | None = None,
                 window: int | None = None, stride: int | None = None,
                 features: Sequence[str] = ("rotations", "root_translation"),
                 dtype: torch.dtype = torch.float32, preload: bool = False, select: str | Sequence[str] | None = None,
                 split: str | None = None, split_ratios: Sequence[float] = (0.8, 0.1, 0.1), split_seed: int = 0,
                 assemble_on: str | torch.device | None = None):
        self.path = Path(path)
        self.assemble_on = None if assemble_on is None else str(torch.device(assemble_on))
        if self.assemble_on is not None and preload:
            raise ValueError("assemble_on makes each batch's features in the collate step; preload=True makes them all "
                             "here: choose one")
        self.features = tuple(dict.fromkeys((features,) if isinstance(features, str) else features))
        self.dtype = dtype
        self.preload = bool(preload)
        if not (isinstance(dtype, torch.dtype) and dtype.is_floating_point):
            raise ValueError(f"dtype must be a floating torch dtype, got {dtype!r}")
        self.window, self.stride = _window_and_stride(window, stride)

        self._db: MotionDatabase | None = None
        self._db_pid: int | None = None
        with MotionDatabase.open(self.path) as db:
            clip_table = db.clip_table()
            stored = self._read_layout(db)
            self._check_features()
            keep = selection_mask(clip_table, self.path, self.frame_columns, clips=clips, where=where, select=select,
                                  split=split, split_ratios=split_ratios, split_seed=split_seed)
            self._take(clip_table, np.flatnonzero(keep))
            self._raw: dict[int, tuple[str, ...]] = {k: self._arrays_needed(stored[k])
                                                     for k in sorted(set(self._skel.tolist()))}
            if self.preload:
                self._load_all(db)
        self.num_clips = len(self.indices)
        self._make_windows()

    # -- construction, step by step ---------------------------------------------------------------
    def _read_layout(self, db: MotionDatabase) -> dict[int, set[str]]:
        """The database's skeletons, columns, trajectory joints and units; returns the frame
        arrays stored per skeleton."""
        self.skeletons: list[Skeleton] = db.skeletons
        self.frame_columns: tuple[str, ...] = tuple(db.frame_columns)
        self.columns: dict[str, str] = dict(db.columns)
        info = [db.skeleton_info(k) for k in range(len(self.skeletons))]
        self.trajectory_joints: dict[int, int] = (
            {k: trajectory_joint(db, k, sk) for k, sk in enumerate(self.skeletons)}
            if {"trajectory", "trajectory_velocity"} & set(self.features) else {})
        self.units: dict[int, str] = {k: i.units for k, i in enumerate(info)}
        return {k: set(i.frame_arrays) for k, i in enumerate(info)}

    def _take(self, clip_table, sel: np.ndarray) -> None:
        """Keep the clips of rows ``sel``: their rows, names, metadata and the columns items read."""
        self.indices = sel.astype(np.int64)
        chosen = clip_table.take(sel)
        self.table = chosen.to_dict()
        self._labels = chosen.labels
        self.names = [str(n) for n in self.table["name"]]
        self._skel = self.table["skeleton"].astype(np.int64)
        self._row0 = self.table["start"].astype(np.int64)
        self._len = self.table["length"].astype(np.int64)
        self._fps = self.table["fps"].astype(np.float64)
        self._names_arr = np.array(self.names, dtype=str) if self.names else np.zeros(0, dtype="<U1")

    def _arrays_needed(self, stored: set[str]) -> tuple[str, ...]:
        """The stored arrays a skeleton's clips are read from to make the features (``stored``:
        what that skeleton's frames hold)."""
        features = set(self.features)
        need = []
        if features & ({"rotations", "rotations_6d", "translations"} | NEEDS_FK):
            need.append("rotations")
        if features & ({"root_translation", "root_velocity", "translations"} | NEEDS_FK):
            need.append("root_translation")
        if "translations" in stored and features & ({"translations"} | NEEDS_FK):
            need.append("translations")
        need += [f for f in self.features if f in self.frame_columns]
        return tuple(need)

    def _make_windows(self) -> None:
        """The items: one per clip, or the windows of ``window`` frames every ``stride`` frames."""
        window, stride = self.window, self.stride
        if window is None:
            self._win_clip = self._win_start = None
            self.num_too_short, self.too_short = 0, ()
            return
        counts = np.where(self._len >= window, (self._len - window) // stride + 1, 0)
        self._win_clip = np.repeat(np.arange(self.num_clips, dtype=np.int64), counts)
        self._win_start = ranges_to_rows(np.zeros(len(counts), np.int64), counts) * stride
        short = np.flatnonzero(counts == 0)
        self.num_too_short = int(len(short))
        self.too_short = tuple(self.names[i] for i in short)
        if self.num_clips and not counts.any():  # an empty dataset would only fail later, in the loader
            raise DatasetError(f"{self.path}: no selected clip is as long as window={window} frames "
                               f"(the longest of the {self.num_clips} has {int(self._len.max())})")

    # -- checks and files -------------------------------------------------------------------------
    def _check_features(self) -> None:
        available = (*BUILTIN_FEATURES, *self.frame_columns)
        bad = [f for f in self.features if f not in available]
        if bad:
            raise ValueError(f"unknown feature {bad[0]!r}; this database offers: {', '.join(available)}")
        clash = [f for f in self.features if f in ITEM_KEYS or f in ("mask", "lengths")]
        if clash:
            raise ValueError(f"per-frame column {clash[0]!r} has the name of an item key; it cannot be a feature")

    def _database(self) -> MotionDatabase:
        """This process's open database, opened on first use (and anew in a forked child)."""
        pid = os.getpid()
        if self._db is not None and self._db_pid != pid:
            # inherited across fork: never read through the parent's handle
            try:
                self._db.close()
            except Exception:
                pass
            self._db = None
        if self._db is None:
            self._db = MotionDatabase.open(self.path)
            self._db_pid = pid
        return self._db

    def close(self) -> None:
        """Close this process's HDF5 file, if open (it reopens on the next read)."""
        if self._db is not None and self._db_pid == os.getpid():
            self._db.close()
        self._db, self._db_pid = None, None

    def __getstate__(self) -> dict:
        state = self.__dict__.copy()
        state.update(_db=None, _db_pid=None)  # open files never travel
        return state

    def __del__(self):
        try:
            self.close()
        except Exception:
            pass

    # -- preloading -----------------------------------------------------------------------------
    def _load_all(self, db: MotionDatabase) -> None:
        """Read the selected clips and compute their features, per skeleton, once."""
        self._pre: dict[int, dict[str, torch.Tensor]] = {}
        self._pre_offset = np.zeros(len(self.indices), dtype=np.int64)
        for k, need in self._raw.items():
            clips = np.flatnonzero(self._skel == k)
            starts, lengths = self._row0[clips], self._len[clips]
            raw = {n: torch.from_numpy(db.frame_array(k, n).gather(starts, lengths)).to(self.dtype) for n in need}
            offs = lengths_to_starts(lengths)
            self._pre_offset[clips] = offs
            N = int(lengths.sum())
            fps = torch.from_numpy(np.repeat(self._fps[clips], lengths)).to(self.dtype)
            first = torch.zeros(N, dtype=torch.bool)
            first[torch.from_numpy(offs[lengths > 0])] = True
            self._pre[k] = derive_features(raw, self.features, self.skeletons[k], fps, first, first,
                                   self.trajectory_joints.get(k, 0))

    # -- items ------------------------------------------------------------------------------------
    def __len__(self) -> int:
        return self.num_clips if self.window is None else len(self._win_clip)

    def _locate(self, i: int) -> tuple[int, int, int]:
        """(selected clip, start frame, number of frames) of item ``i``."""
        n = len(self)
        i = operator.index(i)
        if i < 0:
            i += n
        if not 0 <= i < n:
            raise IndexError(f"item {i} out of range for a dataset of {n}")
        if self.window is None:
            return i, 0, int(self._len[i])
        return int(self._win_clip[i]), int(self._win_start[i]), self.window

    def frames(self, c: int, start: int, n: int) -> dict[str, torch.Tensor]:
        """The features of frames ``start:start+n`` of selected clip ``c`` (``0 <= c < num_clips``)."""
        return self._fetch([(c, start, n)])[0]

    def _fetch(self, parts: Sequence[tuple[int, int, int]], device: torch.device | None = None
               ) -> list[dict[str, torch.Tensor]]:
        """Features of several ``(clip, start, n)`` frame ranges; one feature computation per skeleton.

        Each range reads just its rows from the file (and the row before it when velocities
        are asked and it does not start its clip); the rows of all ranges on one skeleton are
        then concatenated so that forward kinematics runs once over all of them. With a
        ``device``, the rows are assembled and the features computed there.
        """
        if self.preload:
            out = []
            for c, start, n in parts:
                s = int(self._pre_offset[c]) + start
                out.append({f: t[s:s + n].clone() for f, t in self._pre[int(self._skel[c])].items()})
            return out
        results: list[dict[str, torch.Tensor] | None] = [None] * len(parts)
        by_skeleton: dict[int, list[int]] = {}
        for p, (c, _, _) in enumerate(parts):
            by_skeleton.setdefault(int(self._skel[c]), []).append(p)
        vel = bool(VELOCITY & set(self.features))
        for k, members in by_skeleton.items():
            ctxs, sizes, fps, clip_first, los = [], [], [], [], []
            for p in members:
                c, start, n = parts[p]
                ctx = 1 if (vel and start > 0) else 0  # the frame before, for velocities
                los.append(int(self._row0[c]) + start - ctx)
                ctxs.append(ctx)
                sizes.append(n + ctx)
                fps.append(float(self._fps[c]))
                clip_first.append(start == 0)
            # every range of the skeleton in one read per array (an alignment store assembles them at once)
            los_a, sizes_a = np.array(los, np.int64), np.array(sizes, np.int64)
            if device is None:  # an alignment store assembles only the arrays asked for
                raw = {name: torch.from_numpy(np.ascontiguousarray(a))
                       for name, a in self._database().assembled(k, los_a, sizes_a, self._raw[k],
                                                                  torch.get_num_threads()).items()}
            else:
                raw = self._database().assembled_on(k, los_a, sizes_a, device, self._raw[k])
            sizes_t = torch.tensor(sizes, dtype=torch.int64)
            seg_first = torch.zeros(int(sizes_t.sum()), dtype=torch.bool)
            offsets = torch.cumsum(sizes_t, 0) - sizes_t
            seg_first[offsets[sizes_t > 0]] = True
            clip_first_rows = seg_first.clone()
            clip_first_rows[offsets[(sizes_t > 0) & ~torch.tensor(clip_first)]] = False
            frames = {name: v.to(self.dtype) for name, v in raw.items()}
            # numpy's repeat: torch's runs on its thread pool, which costs more than it saves here
            fps_rows = torch.from_numpy(np.repeat(np.asarray(fps, np.float64), sizes)).to(self.dtype)
            if device is not None:
                fps_rows, clip_first_rows, seg_first = (x.to(device) for x in (fps_rows, clip_first_rows, seg_first))
            derived = derive_features(frames, self.features, self.skeletons[k], fps_rows, clip_first_rows, seg_first,
                              self.trajectory_joints.get(k, 0))
            for p, o, size, ctx in zip(members, offsets.tolist(), sizes, ctxs):
                results[p] = {f: t[o + ctx:o + size] for f, t in derived.items()}
        return results

    def _item(self, c: int, start: int, n: int, frames: dict[str, torch.Tensor]) -> dict:
        item: dict[str, Any] = frames
        item.update(name=str(self._names_arr[c]), length=n, fps=float(self._fps[c]), index=int(self.indices[c]),
                    start=start, skeleton=int(self._skel[c]))
        if "labels" in self.features:
            item["labels"] = dict(self._labels[c])
        return item

    def __getitem__(self, i: int) -> dict:
        c, start, n = self._locate(i)
        return self._item(c, start, n, self._fetch([(c, start, n)])[0])

    def __getitems__(self, indices: Sequence[int]) -> list[dict]:
        """Items ``[self[i] for i in indices]``, their features computed in one batch.

        ``DataLoader`` calls this with each batch's indices (torch 2.x), so forward kinematics
        runs once per batch instead of once per item; the items equal ``self[i]`` exactly.
        """
        where = [self._locate(i) for i in indices]
        if self.assemble_on is not None:  # the features come in collate(), for the whole batch on the device
            return [self._item(c, start, n, {"_range": (c, start, n)}) for c, start, n in where]
        return [self._item(c, start, n, f) for (c, start, n), f in zip(where, self._fetch(where))]

    def collate(self, items: Sequence[dict]) -> dict:
        """The ``collate_fn`` for this dataset: :func:`collate_motion` of the items, whose features
        are first made for the whole batch on ``assemble_on`` when the dataset has one (see the
        class docstring); the batch's tensors are then on that device."""
        pending = [it for it in items if "_range" in it]
        if pending:
            device = torch.device(self.assemble_on)
            if device.type != "cpu" and torch.utils.data.get_worker_info() is not None:
                raise DatasetError(f"{self.path}: assemble_on={self.assemble_on!r} makes each batch on the device in the "
                                   "collate step, which a DataLoader worker process cannot: use num_workers=0 (its "
                                   "reads are an alignment store's parts, a few bytes per frame)")
            made = self._fetch([it["_range"] for it in pending], device)
            for it, f in zip(pending, made):
                del it["_range"]
                it.update(f)
        return collate_motion(list(items))

    def batch_sampler(self, batch_size: int, shuffle: bool = False, seed: int = 0, drop_last: bool = False):
        """A ``DataLoader`` ``batch_sampler`` whose batches each hold items of one skeleton
        topology (so that :func:`collate_motion` can stack their joints), for a dataset whose
        clips are on several: ``DataLoader(ds, batch_sampler=ds.batch_sampler(32, shuffle=True),
        collate_fn=collate_motion)`` (:class:`~torchsplice.data.sampler.SkeletonBatchSampler`)."""
        groups: dict[int, list[int]] = {}
        for i, g in enumerate(self.item_topologies().tolist()):
            groups.setdefault(g, []).append(i)
        return SkeletonBatchSampler(list(groups.values()), batch_size, shuffle, seed, drop_last)

    def item_topologies(self) -> np.ndarray:
        """``(len(self),)`` int64: for each item, the first skeleton id of its skeleton's topology
        (items of equal values stack in one batch)."""
        topology: dict[int, int] = {}
        for k in sorted(set(self._skel.tolist())):
            topology[k] = next((g for g in topology if self.skeletons[g].same_topology(self.skeletons[k])), k)
        skel = self._skel if self.window is None else self._skel[self._win_clip]
        return np.array([topology[k] for k in np.asarray(skel).tolist()], np.int64)

    @property
    def skeleton(self) -> Skeleton:
        """The one skeleton every selected clip is on (an error if they are on several)."""
        ks = sorted(set(self._skel.tolist()))
        if len(ks) != 1:
            raise DatasetError(f"{self.path}: the selected clips are on skeletons {ks}; filter with where={{'skeleton': k}}")
        return self.skeletons[ks[0]]

    def statistics(self, features: Sequence[str] | None = None,
                   batch_frames: int = 1 << 16) -> dict[str, FeatureStatistics]:
        """Per-dimension mean and standard deviation of ``features`` over the selected clips.

        Args:
            features: feature names (any of this database's per-frame features, asked for at
                construction or not); default: this dataset's features (``labels`` left out).
            batch_frames: about how many frames are read and computed at once (whole clips).

        Returns ``{name: FeatureStatistics(mean, std, frames)}``, float64 tensors of the
        feature's per-frame shape (``(J, 6)`` for ``rotations_6d``, ``(3,)`` for
        ``trajectory``): over every frame of every selected clip, whole clips whatever
        ``window`` says (so overlapping windows do not count frames twice), ``ddof=0``. Clips
        are read and their features computed in batches of about ``batch_frames`` frames,
        in float64 (one forward kinematics per batch), and the batches' moments are merged
        exactly (Chan et al.'s pairwise update), so the result does not depend on
        ``batch_frames`` beyond rounding.

        Normalise with ``(x - mean) / torch.where(std > eps, std, 1)`` (``eps`` e.g. 1e-6): a dimension
        that never changes (a joint's fixed translation, Bandai Namco's ``joint_Root``) has ``std == 0``.

        The selected clips must share one skeleton topology and one unit (means of different
        joints or units mean nothing), and their values must be finite (a per-frame column is
        NaN on clips that do not give it, such as the sources copied into a spliced database):
        otherwise :class:`DatasetError` names the skeletons and clips, and says how to filter.
        """
        names = [f for f in (self.features if features is None else ([features] if isinstance(features, str) else features))
                 if f not in NOT_PER_FRAME]
        names = list(dict.fromkeys(names))
        if not names:
            raise ValueError("statistics need at least one per-frame feature (labels have none)")
        available = (*BUILTIN_FEATURES, *self.frame_columns)
        bad = [f for f in names if f not in available]
        if bad:
            raise ValueError(f"unknown feature {bad[0]!r}; this database offers: {', '.join(available)}")
        ks = sorted(set(self._skel.tolist()))
        for k in ks[1:]:
            if not self.skeletons[k].same_topology(self.skeletons[ks[0]]):
                a, b = (str(self._names_arr[int(np.flatnonzero(self._skel == x)[0])]) for x in (ks[0], k))
                raise DatasetError(f"{self.path}: statistics need clips of one skeleton topology; the selected clips "
                                   f"are on skeletons {ks} (skeleton {k}, clip {b!r}, against {ks[0]}, clip {a!r}: "
                                   f"{self.skeletons[ks[0]].mismatch(self.skeletons[k])}); filter with where={{'skeleton': k}}")
        units = sorted({self.units.get(k, "") for k in ks})
        if len(units) > 1:
            raise DatasetError(f"{self.path}: statistics need clips of one unit; the selected clips are in {units} "
                               "(convert them on import, see torchsplice.ops.units, or filter with where={'skeleton': k})")
        same = set(names) <= set(self.features) and self.dtype == torch.float64
        ds = self if same else MotionDataset(self.path, clips=self.indices.tolist(), features=names, dtype=torch.float64)
        order = np.argsort(ds._skel, kind="stable")  # batches of one skeleton: one FK each
        count = 0
        mean: dict[str, torch.Tensor] = {}
        m2: dict[str, torch.Tensor] = {}
        lo = 0
        while lo < len(order):
            hi, frames = lo, 0
            while hi < len(order) and (hi == lo or frames + int(ds._len[order[hi]]) <= batch_frames):
                frames += int(ds._len[order[hi]])
                hi += 1
            parts = [(int(c), 0, int(ds._len[c])) for c in order[lo:hi] if ds._len[c] > 0]
            lo = hi
            if not parts:
                continue
            got = ds._fetch(parts)
            n_b = sum(p[2] for p in parts)
            n = count + n_b
            for f in names:
                x = torch.cat([g[f] for g in got]).to(torch.float64)
                bad = ~torch.isfinite(x.reshape(x.shape[0], -1)).all(dim=1)
                if bool(bad.any()):  # a NaN would poison every mean it enters: name the clip instead
                    row = int(bad.nonzero()[0])
                    ends = np.cumsum([p[2] for p in parts])
                    k = int(np.searchsorted(ends, row, side="right"))
                    frame = row - (int(ends[k - 1]) if k else 0)
                    raise DatasetError(f"{self.path}: clip {ds.names[parts[k][0]]!r}: non-finite value in {f} at frame "
                                       f"{frame}; statistics need finite values (leave the clip out with clips= or where=)")
                mb = x.mean(0)
                m2b = ((x - mb) ** 2).sum(0)
                if count == 0:
                    mean[f], m2[f] = mb, m2b
                else:
                    delta = mb - mean[f]
                    mean[f] = mean[f] + delta * (n_b / n)
                    m2[f] = m2[f] + m2b + delta ** 2 * (count * n_b / n)
            count = n
        if count == 0:
            raise DatasetError(f"{self.path}: the selected clips have no frames to compute statistics over")
        return {f: FeatureStatistics(mean[f], (m2[f] / count).sqrt(), count) for f in names}

    def __repr__(self) -> str:
        what = "clips" if self.window is None else f"windows of {self.window} (stride {self.stride})"
        return (f"MotionDataset({str(self.path)!r}, {len(self)} {what} from {self.num_clips} clips, "
                f"features={list(self.features)})")


# --------------------------------------------------------------------------------------------
# batching
# --------------------------------------------------------------------------------------------
