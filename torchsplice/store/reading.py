"""Reading clips from a motion database: the read half of
:class:`~torchsplice.store.database.MotionDatabase` (:class:`Reading`), the padded
:class:`ClipBatch` (:class:`~torchsplice.store.frame_array.FrameArray`, rows of one stored
per-frame array, lives in :mod:`torchsplice.store.frame_array`).

Reads turn HDF5's ``OSError`` (a chunk that does not decompress, a truncated file) into one
:class:`~torchsplice.core.errors.DatabaseError` line naming the file (:func:`~torchsplice.store.frame_array.reads`); reads of
frames name the clip too.
"""

from __future__ import annotations

import difflib
import json
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Iterator, Sequence

import h5py
import numpy as np
import torch

from ..core.errors import DatabaseError
from ..core.ranges import lengths_to_starts
from ..core.motion import Motion
from ..core.skeleton import Skeleton
from ..specs import DatasetSpec, detect_spec
from .schema import FRAME_ARRAYS, CLIPS, COLUMNS, cap, short, skeleton_path
from .select import names_or_selector, select_clips
from .state import DatabaseState
from .frame_array import FrameArray, reads, virtual_files
from .table import ClipTable, SkeletonInfo, json_value, run_record

__all__ = ["Reading", "ClipBatch", "FrameArray", "reads", "virtual_files"]


@dataclass
class ClipBatch:
    """Clips of one skeleton, padded to a common length.

    Attributes:
        rotations: ``(B, T, J, 4)`` local rotations, WXYZ; padding repeats each clip's last frame.
        root_translation: ``(B, T, 3)``.
        translations: ``(B, T, J, 3)`` or ``None`` (see :class:`~torchsplice.core.motion.Motion`).
        lengths: ``(B,)`` int64 number of real frames per clip.
        mask: ``(B, T)`` bool, True on real frames.
        fps: ``(B,)`` float64.
        names: the clips' names; ``indices``: their row numbers in the database.
        skeleton: the shared :class:`Skeleton`.
    """

    rotations: torch.Tensor
    root_translation: torch.Tensor
    translations: torch.Tensor | None
    lengths: torch.Tensor
    mask: torch.Tensor
    fps: torch.Tensor
    names: list[str]
    indices: list[int]
    skeleton: Skeleton

    def __len__(self) -> int:
        return len(self.names)

    def motion(self, b: int) -> Motion:
        """Clip ``b`` of the batch, without padding."""
        n = int(self.lengths[b])
        return Motion(
            self.skeleton,
            self.rotations[b, :n],
            self.root_translation[b, :n],
            float(self.fps[b]),
            None if self.translations is None else self.translations[b, :n],
            name=self.names[b],
        )


class Reading(DatabaseState):
    """The read methods of :class:`~torchsplice.store.database.MotionDatabase` (a mixin: the
    database's state, file and opening live there)."""

    def _unreadable(self, exc: BaseException, what: str) -> DatabaseError:
        return DatabaseError(f"{self.path}: damaged database: cannot read {what} ({short(exc)})")

    def _frames_error(self, exc: OSError, k: int, rows) -> DatabaseError:
        """The error for a failed read of skeleton ``k``'s frames: names the first of the clips
        ``rows`` (``None``: every clip of the skeleton) whose own frames cannot be read."""
        try:
            c = self.h5[CLIPS]
            start, length = c["start"][()], c["length"][()]
            if rows is None:
                rows = np.flatnonzero(c["skeleton"][()] == k)
            g = self.h5[skeleton_path(k)]
            sets = [n for n in (*FRAME_ARRAYS, *self.frame_columns) if n in g]
            for i in sorted((int(i) for i in rows), key=lambda i: int(start[i])):
                s, n = int(start[i]), int(length[i])
                for name in sets:
                    try:
                        g[name][s : s + n]
                    except OSError as inner:
                        return self._unreadable(inner, f"the frames of clip {cap(self.names[i], 60)}")
        except (OSError, DatabaseError):
            pass
        return self._unreadable(exc, f"the frames of skeleton {k}")

    @contextmanager
    def _frames(self, k: int, rows=None):
        """Reads of skeleton ``k``'s frames for the clips ``rows``: a damaged chunk is one
        :class:`DatabaseError` naming the file and the clip."""
        try:
            yield
        except OSError as exc:
            raise self._frames_error(exc, k, rows) from None

    @property
    @reads
    def names(self) -> list[str]:
        """Every clip's name, in row order."""
        if self._names is None:
            self._names = list(self.h5[f"{CLIPS}/name"].asstr()[()])
        return self._names + [m.name for m, *_ in self._staged]

    def index(self, clip: str | int) -> int:
        """Row number of a clip given by name or row number; a clear error otherwise."""
        if isinstance(clip, (int, np.integer)):
            if not 0 <= clip < len(self):
                raise DatabaseError(f"{self.path}: no clip number {clip} (the database has {len(self)})")
            return int(clip)
        index = self._index_map()
        if clip not in index:
            close = [n for n in index if clip.lower() in n.lower()][:5] or difflib.get_close_matches(
                clip, list(index), n=5
            )
            hint = f"; similar: {', '.join(close)}" if close else "; {info} lists the clips"
            raise DatabaseError(f"{self.path}: no clip named {clip!r}{hint}", options=("info",) if not close else ())
        return index[clip]

    def _index_map(self) -> dict[str, int]:
        """Name -> row, built once per open and kept up to date by :meth:`append`."""
        if self._name_index is None:
            self._name_index = {n: i for i, n in enumerate(self.names)}
        return self._name_index

    TABLE_AFTER_INFOS = 16
    """``clip_info`` reads a clip's row column by column until it has been asked this many times
    on one open database of at most :attr:`TABLE_AFTER_ROWS` clips; then it reads the clip
    table once (:meth:`clip_table`) and answers from it, as it does whenever the table is read."""
    TABLE_AFTER_ROWS = 200_000

    @reads
    def clip_info(self, clip: str | int) -> dict:
        """Metadata of one clip: name, source, role, labels, skeleton, start, length, fps, and
        every extra column (Python values)."""
        i = self.index(clip)
        self._require_flushed(i)
        self._table_written()
        table = getattr(self, "_clip_table", None)
        if table is None and self._info_reads >= self.TABLE_AFTER_INFOS and len(self) <= self.TABLE_AFTER_ROWS:
            table = self.clip_table()
        if table is not None and i < len(table) and table.kinds.keys() == self.columns.keys():
            return table.info(i)  # rows are only ever added: a row of the table read earlier holds
        self._info_reads += 1
        return ClipTable.from_columns(self._table_rows(i, i + 1), self.columns, self.path).info(0)

    def _table_rows(self, lo: int, hi: int) -> dict[str, np.ndarray]:
        """Clip-table rows ``lo:hi`` as stored, every column (text decoded, labels as JSON text)."""
        c = self.h5[CLIPS]
        return {
            k: (c[k].asstr()[lo:hi] if h5py.check_string_dtype(c[k].dtype) else c[k][lo:hi])
            for k in [*COLUMNS, *self.columns]
        }

    @reads
    def table(self) -> dict[str, np.ndarray]:
        """Every metadata column, extra ones too, as an array (labels as JSON strings, each
        checked to be a JSON object, so that callers may ``json.loads`` them); see
        :meth:`clip_table` for the typed table, labels decoded."""
        return self.clip_table().to_dict()

    @reads
    def clip_table(self) -> ClipTable:
        """The clip table, typed: every column an array in row order, labels decoded (a row
        whose labels are not a JSON object: one :class:`DatabaseError` naming the clip). Read
        once per open database and kept until clips are added; its arrays are read-only."""
        self.flush()
        self._table_written()
        c = self.h5[CLIPS]
        cached = getattr(self, "_clip_table", None)
        if cached is not None and len(cached) == c["name"].shape[0]:  # rows are only ever added
            return cached
        self._clip_table = ClipTable.from_columns(self._table_rows(0, c["name"].shape[0]), self.columns, self.path)
        return self._clip_table

    @reads
    def table_slice(self, lo: int, hi: int) -> dict[str, np.ndarray]:
        """Clip-table rows ``lo:hi``, every column (the declared extra ones too; text decoded,
        labels as their JSON text), read from the file without the whole table: for readers of
        millions of clips that go through them a slice at a time."""
        self.flush()
        self._table_written()
        return self._table_rows(lo, hi)

    def __contains__(self, clip) -> bool:
        """Whether the database holds a clip named ``clip``."""
        return isinstance(clip, str) and clip in self._index_map()

    def run_record(self) -> dict | str | None:
        """The run record (the root attribute ``run``, JSON written by ``splice-all``) as a dict;
        ``None`` when the file has none, the raw text when it is not a JSON object."""
        return run_record(self.attrs.get("run"))

    @reads
    def skeleton_info(self, skeleton: int) -> SkeletonInfo:
        """What the file records with skeleton ``k``: units, up axis, spec, stored frame arrays."""
        sk = self._skeletons[skeleton]  # an IndexError for an unknown skeleton
        g = self.h5[skeleton_path(skeleton)]
        text = self.spec_json(skeleton)
        spec = json.loads(text or "{}")
        return SkeletonInfo(
            id=skeleton,
            skeleton=sk,
            units=str(g.attrs.get("units", "")),
            up_axis=str(g.attrs.get("up_axis", "")),
            spec_json=text,
            spec_name=spec.get("name", "") if isinstance(spec, dict) else "",
            frame_arrays=tuple(n for n in (*FRAME_ARRAYS, *self.frame_columns) if n in g),
            dtype=np.dtype(g["rotations"].dtype),
        )

    def stored_spec(self, skeleton: int) -> DatasetSpec | None:
        """The dataset spec stored with skeleton ``k``, or ``None`` where none was stored."""
        text = self.spec_json(skeleton)
        return DatasetSpec.from_json(text) if text else None

    def spec(self, skeleton: int) -> DatasetSpec:
        """The dataset spec of skeleton ``k``: the one stored with it, else one detected for it
        (:func:`~torchsplice.specs.detect_spec`, which guesses one where no shipped spec fits;
        a :class:`~torchsplice.core.errors.SpecError` when nothing fits)."""
        spec = self.stored_spec(skeleton)
        return spec if spec is not None else detect_spec(self._skeletons[skeleton])

    def frame_array(self, skeleton: int, name: str) -> FrameArray:
        """The per-frame array ``name`` of skeleton ``k`` (one of :attr:`SkeletonInfo.frame_arrays`),
        for readers that take rows of many clips (see :class:`FrameArray`)."""
        g = self.h5[skeleton_path(skeleton)]
        if name not in (*FRAME_ARRAYS, *self.frame_columns) or name not in g:
            raise DatabaseError(f"{self.path}: skeleton {skeleton} stores no per-frame array {name!r}")
        if name in FRAME_ARRAYS and self.store == "alignment":
            return self.assembled_array(skeleton, name)
        return FrameArray(g[name])

    @reads
    def read_frame_column(self, clip: str | int, name: str) -> np.ndarray:
        """A clip's values ``(T,)`` of the per-frame column ``name``."""
        if name not in self.frame_columns:
            raise DatabaseError(
                f"{self.path}: no per-frame column {name!r} (has: {', '.join(self.frame_columns) or 'none'})"
            )
        info = self.clip_info(clip)
        with self._frames(info["skeleton"], [self.index(clip)]):
            return self.h5[f"{skeleton_path(info['skeleton'])}/{name}"][info["start"] : info["start"] + info["length"]]

    def _table_written(self) -> None:
        if self._resumable and self._h5 is not None:
            raise DatabaseError(f"{self.path}: is being written (its clip table is written when it is closed)")

    def _require_flushed(self, i: int) -> None:
        if i >= self._flushed:
            self.flush()

    @reads
    def packed(self, skeleton: int = 0) -> dict[str, np.ndarray]:
        """Every frame of skeleton ``k`` as whole arrays: ``rotations``, ``root_translation``,
        ``translations`` (when stored) and the per-frame columns, rows as in the file (read at
        once: meant for a splice job's parts and other small files)."""
        g = self.h5[skeleton_path(skeleton)]
        if self.store == "alignment":
            return self.whole_frames(skeleton)
        with self._frames(skeleton):
            return {n: g[n][()] for n in (*FRAME_ARRAYS, *self.frame_columns) if n in g}

    @reads
    def read_many(self, clips: Sequence[str | int], dtype: torch.dtype = torch.float32) -> list[Motion]:
        """Several clips as :class:`Motion` objects, in the order asked; the metadata table is
        read once (faster than :meth:`read` per clip)."""
        idx = [self.index(c) for c in clips]
        if not idx:
            return []
        self._require_flushed(max(idx))
        ct = self.clip_table()  # labels decoded once
        t = ct.to_dict()
        blocks: dict[int, tuple[int, dict]] = {}  # skeleton -> (first row, whole block of its frames)
        if self.store == "alignment":  # assembled, the clips of one skeleton at once
            return self._read_assembled(idx, ct, dtype)
        for k in sorted({int(t["skeleton"][i]) for i in idx}):
            mine = [i for i in idx if int(t["skeleton"][i]) == k]
            lo = min(int(t["start"][i]) for i in mine)
            hi = max(int(t["start"][i] + t["length"][i]) for i in mine)
            if hi - lo <= 2 * sum(int(t["length"][i]) for i in mine):  # one read, each chunk decompressed once
                g = self.h5[skeleton_path(k)]
                with self._frames(k, mine):
                    blocks[k] = (lo, {n: g[n][lo:hi] for n in FRAME_ARRAYS if n in g})
        out = []
        for i in idx:
            k, s, n = int(t["skeleton"][i]), int(t["start"][i]), int(t["length"][i])
            g = self.h5[skeleton_path(k)]
            lo, block = blocks.get(k, (0, None))

            def get(name):
                with self._frames(k, [i]):
                    a = block[name][s - lo : s - lo + n] if block is not None else g[name][s : s + n]
                return torch.from_numpy(np.ascontiguousarray(a)).to(dtype)

            out.append(
                Motion(
                    skeleton=self._skeletons[k],
                    rotations=get("rotations"),
                    root_translation=get("root_translation"),
                    translations=get("translations") if "translations" in g else None,
                    fps=float(t["fps"][i]),
                    name=str(t["name"][i]),
                    source=str(t["source"][i]),
                    role=str(t["role"][i]),
                    labels=dict(ct.labels[i]),
                )
            )
        return out

    def _read_assembled(self, idx: list[int], ct: ClipTable, dtype) -> list[Motion]:
        """:meth:`read_many` of an alignment store: each skeleton's clips assembled at once."""
        out: dict[int, Motion] = {}
        for k in sorted({int(ct.skeleton[i]) for i in idx}):
            mine = list(dict.fromkeys(i for i in idx if int(ct.skeleton[i]) == k))
            starts, lengths = ct.start[mine].astype(np.int64), ct.length[mine].astype(np.int64)
            made = self.assembled(k, starts, lengths)
            at = lengths_to_starts(lengths)
            for i, a, n in zip(mine, at, lengths):

                def get(name):
                    return torch.from_numpy(np.ascontiguousarray(made[name][a : a + n])).to(dtype)

                out[i] = Motion(
                    skeleton=self._skeletons[k],
                    rotations=get("rotations"),
                    root_translation=get("root_translation"),
                    translations=get("translations") if "translations" in made else None,
                    fps=float(ct.fps[i]),
                    name=str(ct.name[i]),
                    source=str(ct.source[i]),
                    role=str(ct.role[i]),
                    labels=dict(ct.labels[i]),
                )
        return [out[i] for i in idx]

    @reads
    def read(self, clip: str | int, dtype: torch.dtype = torch.float32, device=None) -> Motion:
        """One clip as a :class:`Motion` (``dtype`` and ``device`` as asked)."""
        info = self.clip_info(clip)
        g = self.h5[skeleton_path(info["skeleton"])]
        s, n = info["start"], info["length"]
        made = self.assembled(info["skeleton"], [s], [n]) if self.store == "alignment" else None

        def get(name):
            if made is not None:
                return torch.from_numpy(made[name]).to(device=device, dtype=dtype)
            with self._frames(info["skeleton"], [self.index(clip)]):
                a = g[name][s : s + n]
            return torch.from_numpy(a).to(device=device, dtype=dtype)

        return Motion(
            skeleton=self._skeletons[info["skeleton"]],
            rotations=get("rotations"),
            root_translation=get("root_translation"),
            translations=get("translations") if "translations" in g else None,
            fps=info["fps"],
            name=info["name"],
            source=info["source"],
            role=info["role"],
            labels=info["labels"],
        )

    @reads
    def read_batch(self, clips: Sequence[str | int], dtype: torch.dtype = torch.float32, device=None) -> ClipBatch:
        """Several clips of one skeleton as a padded :class:`ClipBatch` (``device``: on it; an
        alignment store's clips asked for on a GPU are assembled there)."""
        if len(clips) == 0:
            raise DatabaseError(f"{self.path}: an empty batch was asked for")
        idx = [self.index(c) for c in clips]
        self._require_flushed(max(idx))
        col = self.h5[CLIPS]
        sk_ids = col["skeleton"][()][idx]
        if len(set(sk_ids.tolist())) != 1:
            raise DatabaseError(
                f"{self.path}: clips of one batch must share a skeleton, got skeletons {sorted(set(sk_ids.tolist()))}"
            )
        k = int(sk_ids[0])
        starts = col["start"][()][idx].astype(np.int64)
        lengths = col["length"][()][idx].astype(np.int64)
        g = self.h5[skeleton_path(k)]
        lo, hi = int(starts.min()), int((starts + lengths).max())
        T = int(lengths.max())
        # one contiguous read when the clips are close together, else one read per clip
        contiguous = hi - lo <= 2 * int(lengths.sum())
        rows = starts[:, None] + np.minimum(np.arange(T)[None, :], lengths[:, None] - 1)  # edge padding

        made = None
        if self.store == "alignment":  # assembled on the device asked for where it is a GPU
            on_gpu = device is not None and torch.device(device).type == "cuda"
            made = self.assembled_on(k, starts, lengths, device) if on_gpu else self.assembled(k, starts, lengths)

        def gather(name):
            if made is not None:  # packed clip after clip: row r of clip b is offset[b] + r
                offset = lengths_to_starts(lengths)
                at = offset[:, None] + (rows - starts[:, None])
                m = made[name]
                out = (
                    m[torch.as_tensor(at, device=m.device)] if isinstance(m, torch.Tensor) else torch.from_numpy(m[at])
                )
                return out.to(device=device, dtype=dtype)
            ds = g[name]
            with self._frames(k, idx):
                if contiguous:
                    block = ds[lo:hi]
                    out = block[rows - lo]
                else:
                    out = np.stack([ds[s : s + n][np.minimum(np.arange(T), n - 1)] for s, n in zip(starts, lengths)])
            return torch.from_numpy(out).to(device=device, dtype=dtype)

        lengths_t = torch.from_numpy(lengths).to(device)
        all_names = self.names
        return ClipBatch(
            rotations=gather("rotations"),
            root_translation=gather("root_translation"),
            translations=gather("translations") if "translations" in g else None,
            lengths=lengths_t,
            mask=torch.arange(T, device=device)[None, :] < lengths_t[:, None],
            fps=torch.from_numpy(col["fps"][()][idx]).to(device),
            names=[all_names[i] for i in idx],
            indices=idx,
            skeleton=self._skeletons[k],
        )

    @reads
    def batches(
        self,
        clips: Sequence[str | int] | None = None,
        batch_size: int = 32,
        dtype: torch.dtype = torch.float32,
        device=None,
        sort_by_length: bool = False,
    ) -> Iterator[ClipBatch]:
        """Iterate padded batches of up to ``batch_size`` clips, each batch on one skeleton.

        ``clips`` defaults to every clip in row order; ``sort_by_length`` groups clips of
        similar length to reduce padding.
        """
        self.flush()
        idx = [self.index(c) for c in clips] if clips is not None else list(range(len(self)))
        col = self.h5[CLIPS]
        sk = col["skeleton"][()]
        length = col["length"][()]
        for k in sorted(set(sk[idx].tolist())):
            group = [i for i in idx if sk[i] == k]
            if sort_by_length:
                group.sort(key=lambda i: int(length[i]))
            for b in range(0, len(group), batch_size):
                yield self.read_batch(group[b : b + batch_size], dtype=dtype, device=device)

    @reads
    def summary(self, clips: Sequence[str] | None = None, select: Sequence[str] | None = None) -> dict:
        """A JSON-ready description: file attributes, skeletons, roles, every clip and, for a
        database written by ``splice-all``, its run record ``run`` (tool version, command,
        settings, inputs, time; ``None`` otherwise). ``clips`` (names, or selectors as a
        command's clip arguments: :func:`~.select.names_or_selector`) and ``select`` (selectors,
        all of them) keep the ``clips`` list to the clips they choose; the totals stay the
        database's. An unknown name or a selector that selects nothing raises one line."""
        ct = self.clip_table()  # labels decoded once
        keep = self._chosen(ct, clips, select) if clips or select else None
        t = ct.to_dict()
        rows = [
            {
                "name": str(t["name"][i]),
                "frames": int(t["length"][i]),
                "fps": float(t["fps"][i]),
                "duration_s": round(float(t["length"][i] / t["fps"][i]), 3),
                "role": str(t["role"][i]),
                "labels": dict(ct.labels[i]),
                "skeleton": int(t["skeleton"][i]),
                "source": str(t["source"][i]),
                **{n: json_value(t[n][i]) for n in self.columns},
            }
            for i in range(len(t["name"]))
        ]
        roles: dict[str, int] = {}
        for c in rows:
            roles[c["role"] or "(none)"] = roles.get(c["role"] or "(none)", 0) + 1
        skeletons = []
        for k, sk in enumerate(self._skeletons):
            spec = json.loads(self.spec_json(k) or "{}")
            skeletons.append(
                {
                    "id": k,
                    "joints": sk.num_joints,
                    "root": sk.names[0],
                    "spec": spec.get("name", "") if isinstance(spec, dict) else "",
                    "clips": sum(c["skeleton"] == k for c in rows),
                    "joint_names": list(sk.names),
                    "units": str(self.h5[skeleton_path(k)].attrs.get("units", "")),
                    "up_axis": str(self.h5[skeleton_path(k)].attrs.get("up_axis", "")),
                    "guessed_roles": (spec.get("guessed") or {}) if isinstance(spec, dict) else {},
                }
            )
        attrs = self.attrs
        return {
            "path": str(self.path),
            "format": attrs.get("format"),
            "schema_version": int(attrs.get("schema_version", 0)),
            "quaternion_order": attrs.get("quaternion_order"),
            "units": attrs.get("units"),
            "up_axis": attrs.get("up_axis"),
            "created_by": attrs.get("created_by"),
            "num_clips": len(rows),
            "num_frames": int(sum(c["frames"] for c in rows)),
            "duration_s": round(sum(c["duration_s"] for c in rows), 3),
            "roles": roles,
            "skeletons": skeletons,
            "clips": rows if keep is None else [c for c in rows if c["name"] in keep],
            "run": run_record(attrs.get("run")),
        }

    def _chosen(self, table: ClipTable, clips: Sequence[str] | None, select: Sequence[str] | None) -> set[str]:
        """The names of :meth:`summary`'s ``clips`` and ``select``."""
        names, chosen = names_or_selector(table, list(clips)) if clips else (None, None)
        for name in names or ():
            self.index(name)  # an unknown name: the database's one line, with similar names
        selectors = list(select or []) + ([chosen] if chosen else [])
        keep = set(names) if names is not None else set(table.names)
        if selectors:
            keep &= {table.names[r] for r in select_clips(table, selectors, "selector", str(self.path))}
        return keep
