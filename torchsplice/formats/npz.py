"""Clips as NumPy ``.npz`` files, for training code and tools that read neither HDF5 nor BVH.

``torchsplice export DB.h5 CLIP ... --format npz`` (or ``--all``) writes one ``.npz`` per clip;
``--packed`` writes all of them into one file, concatenated along frames; ``--features 6d``
adds training features and their normalisation statistics. Every file is read with plain
``numpy.load(path)`` (no pickles: strings are unicode arrays, labels JSON text).

Conventions: quaternions WXYZ (scalar first), local rotations map a joint's frame to its
parent's, lengths in the file's ``units`` (the database's, e.g. ``cm``; see ``import
--units``), the up axis ``up_axis`` (``y`` for every shipped dataset). ``T`` frames, ``J``
joints, ``E`` End Sites. Frame arrays keep the database's float type (float32 unless imported
with ``--float64``), computed in float64; statistics are float64.

One clip per file (``layout == "clip"``):

========================  ==============  ===============================================
key                       shape, type     meaning
========================  ==============  ===============================================
``format``, ``version``   str, int        ``"torchsplice.npz"``, 1
``layout``                str             ``"clip"``
``name``, ``role``        str             the clip's name and role (``locomotion``, ...)
``labels``                str             the clip's labels as a JSON object
``fps``                   float64         frames per second
``units``, ``up_axis``    str             length unit, up axis
``joint_names``           ``(J,)`` str    joint names, topological order
``parents``               ``(J,)`` int64  parent of each joint, -1 for joint 0
``joint_offsets``         ``(J, 3)`` f64  rest offsets in the parent's frame
``end_site_parents``      ``(E,)`` int64  the joint each BVH End Site hangs from
``end_site_offsets``      ``(E, 3)`` f64  End Site offsets in that joint's frame
``trajectory_joint``      int64           index of the joint carrying the character's
                                          trajectory (the spec's ``root`` role: Bandai
                                          Namco ``Hips``; joint 0 for most datasets)
``rotations``             ``(T, J, 4)``   local joint rotations, WXYZ
``root_translation``      ``(T, 3)``      world position of joint 0, as stored
``trajectory``            ``(T, 3)``      world position of ``trajectory_joint``: where the
                                          character is (on Bandai Namco ``root_translation``
                                          is all zeros; this is the one to use)
``translations``          ``(T, J, 3)``   local joint translations (animated ones, or the
                                          rest offsets; row 0 = ``root_translation``)
``positions``             ``(T, J, 3)``   world joint positions by forward kinematics
========================  ==============  ===============================================

Packed (``layout == "packed"``, ``--packed``): the same frame arrays with the frames of every
clip one after the other (``(N, J, 4)``, ``(N, 3)``, ...; ``N`` frames in all), and per clip
(``n`` clips): ``names``, ``roles``, ``labels`` (JSON text each) ``(n,)`` str, ``fps``
``(n,)`` float64, ``skeleton`` ``(n,)`` int64 (the database's skeleton id), ``joint_offsets``
``(n, J, 3)`` (clips of one skeleton topology may differ in bone lengths), and ``offsets``
``(n + 1,)`` int64, the clip boundaries: clip ``i`` is frames ``offsets[i]:offsets[i+1]``.
``joint_names``, ``parents``, ``trajectory_joint``, ``units`` and ``up_axis`` are shared;
``end_site_parents`` ``(E,)`` and ``end_site_offsets`` ``(n, E, 3)`` are present when every
clip has the same End Sites. Only clips of **one skeleton topology** (same joint names and
parents) and one unit pack into one file: another is refused with one line naming the
skeletons; pack each skeleton on its own (``--skeleton K``).

Features (``--features 6d``), as :class:`~torchsplice.data.MotionDataset` computes them:

========================  ==============  ===============================================
``rotations_6d``          ``(T, J, 6)``   the 6D rotation representation of Zhou et al.
                                          2019: the first two columns of each local
                                          rotation matrix, ``(R00, R10, R20, R01, R11,
                                          R21)``; ``torchsplice.core.rotations.
                                          rotation_6d_to_rotmat`` inverts it (Gram-Schmidt)
``velocities``            ``(T, J, 3)``   joint velocities, ``(positions[t] -
                                          positions[t-1]) * fps`` (a clip's first frame
                                          copies its second), units per second
``trajectory_velocity``   ``(T, 3)``      the same for ``trajectory``
``root_velocity``         ``(T, 3)``      the same for ``root_translation``
========================  ==============  ===============================================

and, for every frame array ``X`` of the file (the ones above and the features), ``X_mean``
and ``X_std`` of ``X``'s per-frame shape, float64: the mean and population standard
deviation (``ddof=0``) of each dimension over every frame of **every exported clip** (the
same numbers in each per-clip file, and equal to ``MotionDataset.statistics``), with
``statistics_frames`` and ``statistics_clips`` saying over how much. Normalise for training
with ``(x - x_mean) / np.where(x_std > 1e-6, x_std, 1)`` (a dimension that never changes,
such as a fixed joint's translation, has ``std == 0``) and undo it with ``x * std + mean``.
Features need one skeleton topology and one unit too.

Files are written atomically (beside the target, then renamed), and a file with a value that
is not finite is refused, naming the clip and the array. An export (the ``npz`` format of
:func:`torchsplice.formats.exporters.export_clips`, :mod:`.npz_exporter`) writes all of its files
or none.
"""

from __future__ import annotations

import io
import json
import shutil
import tempfile
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator, Sequence

import numpy as np
import torch

from ..core.errors import TorchspliceError
from ..data.dataset import MotionDataset
from ..store.atomic import atomic_path
from ..store.database import MotionDatabase
from .exporters import select_rows
from .npz_features import FEATURE_SETS

__all__ = ["NPZ_FORMAT", "NPZ_VERSION", "FRAME_ARRAYS", "FEATURE_SETS", "NpzExport", "write_npz", "read_npz",
           "clip_of_packed"]

NPZ_FORMAT = "torchsplice.npz"
NPZ_VERSION = 1
FRAME_ARRAYS = ("rotations", "root_translation", "trajectory", "translations", "positions")
"""The per-frame arrays of every exported clip."""


@dataclass
class NpzExport:
    """The clips of a database to export as ``.npz`` (see the module docstring for the layout).

    Args:
        database: the motion database.
        clips: clip names, in the order wanted; ``None`` for every clip (row order).
        features: a key of :data:`FEATURE_SETS` (``"6d"``) or ``None``.
        skeletons: keep only clips on these database skeletons (``None``: any).

    Raises a one-line :class:`TorchspliceError` for an unknown clip, an empty selection, or
    (with ``features``) clips of several skeleton topologies or units. Reads nothing but the
    table until :meth:`per_clip` or :meth:`packed` is called; :attr:`statistics` is computed on
    first use, in batches (``MotionDataset.statistics``).
    """

    database: Path
    clips: Sequence[str] | None = None
    features: str | None = None
    skeletons: Sequence[int] | None = None
    batch_frames: int = 1 << 16
    _stats: dict | None = field(default=None, init=False, repr=False)

    def __post_init__(self):
        self.database = Path(self.database)
        if self.features is not None and self.features not in FEATURE_SETS:
            raise TorchspliceError(f"unknown feature set {self.features!r} (known: {', '.join(FEATURE_SETS)})")
        with MotionDatabase.open(self.database) as db:
            rows = select_rows(db, self.clips, self.skeletons)
            self._attrs = {}
            for k in range(len(db.skeletons)):
                info = db.skeleton_info(k)
                self._attrs[k] = {"units": info.units, "up_axis": info.up_axis, "spec": info.spec_name, "dtype": info.dtype}
        names = (*FRAME_ARRAYS, *FEATURE_SETS.get(self.features, ()))
        self.frame_arrays: tuple[str, ...] = names
        self._ds = MotionDataset(self.database, clips=rows, features=(*names, "labels"), dtype=torch.float64)
        position = {int(r): c for c, r in enumerate(self._ds.indices)}
        self._order = [position[r] for r in rows]  # dataset clip numbers, in the order asked
        if self.features is not None:
            self.check_one_skeleton("compute feature statistics over")

    # -- what is exported ---------------------------------------------------------------------
    @property
    def names(self) -> list[str]:
        """The exported clips' names, in export order."""
        return [self._ds.names[c] for c in self._order]

    def skeleton_ids(self) -> list[int]:
        """The database skeletons of the exported clips, sorted."""
        return sorted({int(self._ds._skel[c]) for c in self._order})

    def _describe(self, k: int) -> str:
        a = self._attrs[k]
        first = next(self._ds.names[c] for c in self._order if int(self._ds._skel[c]) == k)
        return (f"skeleton {k} ({a['spec'] or 'no spec'}, {self._ds.skeletons[k].num_joints} joints, {a['units'] or '?'}; "
                f"clip {first!r})")

    def check_one_skeleton(self, doing: str) -> None:
        """Refuse, in one line, clips of several skeleton topologies or units (``doing`` says why it matters)."""
        ks = self.skeleton_ids()
        sk = self._ds.skeletons
        for k in ks[1:]:
            if not sk[k].same_topology(sk[ks[0]]) or self._attrs[k]["units"] != self._attrs[ks[0]]["units"]:
                why = sk[ks[0]].mismatch(sk[k]) if not sk[k].same_topology(sk[ks[0]]) else "units differ"
                raise TorchspliceError(
                    f"{self.database}: cannot {doing} clips of different skeletons: {self._describe(ks[0])} and "
                    f"{self._describe(k)} ({why}); export one skeleton at a time ({{skeletons}} with one id, as {{info}} lists them)",
                    options=("skeletons", "info"))

    @property
    def statistics(self) -> dict:
        """``{array: FeatureStatistics}`` over every exported clip (only with ``features``)."""
        if self.features is None:
            return {}
        if self._stats is None:
            self._stats = self._ds.statistics(self.frame_arrays, batch_frames=self.batch_frames)  # finite, or names the clip
        return self._stats

    def _stat_arrays(self) -> dict[str, np.ndarray]:
        out: dict[str, np.ndarray] = {}
        stats = self.statistics
        for f, s in stats.items():
            out[f"{f}_mean"] = s.mean.numpy()
            out[f"{f}_std"] = s.std.numpy()
        if stats:
            out["statistics_frames"] = np.int64(next(iter(stats.values())).frames)
            out["statistics_clips"] = np.int64(len(self._order))
        return out

    def _items(self) -> Iterator[dict]:
        """The exported clips' items (features in float64), in batches of about ``batch_frames`` frames."""
        lo = 0
        while lo < len(self._order):
            hi, frames = lo, 0
            while hi < len(self._order) and (hi == lo or frames + int(self._ds._len[self._order[hi]]) <= self.batch_frames):
                frames += int(self._ds._len[self._order[hi]])
                hi += 1
            for item in self._ds.__getitems__(self._order[lo:hi]):
                self._check_finite(item)
                yield item
            lo = hi

    def _check_finite(self, item: dict) -> None:
        """A one-line error naming the clip, the array and the frame of a value that is not finite."""
        for f in self.frame_arrays:
            x = item[f]
            bad = ~torch.isfinite(x.reshape(x.shape[0], -1)).all(dim=1)
            if bool(bad.any()):
                raise TorchspliceError(f"{self.database}: clip {item['name']!r}: non-finite value in {f} at frame "
                                       f"{int(bad.nonzero()[0])}; nothing written")

    def _skeleton_arrays(self, k: int) -> dict[str, np.ndarray]:
        sk, a = self._ds.skeletons[k], self._attrs[k]
        return {"joint_names": np.array(sk.names, dtype=str), "parents": np.array(sk.parents, dtype=np.int64),
                "trajectory_joint": np.int64(self._ds.trajectory_joints.get(k, 0)),
                "units": np.array(a["units"]), "up_axis": np.array(a["up_axis"])}

    def per_clip(self) -> Iterator[tuple[str, dict[str, np.ndarray]]]:
        """``(name, arrays)`` of each exported clip in the per-clip layout, in export order."""
        stats = self._stat_arrays()
        for item in self._items():
            k = int(item["skeleton"])
            sk, dtype = self._ds.skeletons[k], self._attrs[k]["dtype"]
            arrays = {"format": np.array(NPZ_FORMAT), "version": np.int64(NPZ_VERSION), "layout": np.array("clip"),
                      "name": np.array(item["name"]), "role": np.array(str(self._ds.table["role"][self._clip(item)])),
                      "labels": np.array(json.dumps(item["labels"], sort_keys=True)), "fps": np.float64(item["fps"]),
                      **self._skeleton_arrays(k), "joint_offsets": sk.offsets.numpy().copy(),
                      "end_site_parents": np.array(sk.end_site_parents, dtype=np.int64).reshape(-1),
                      "end_site_offsets": sk.end_site_offsets.numpy().copy().reshape(-1, 3)}
            for f in self.frame_arrays:
                arrays[f] = item[f].numpy().astype(dtype)
            arrays.update(stats)
            yield item["name"], arrays

    def _clip(self, item: dict) -> int:
        return int(np.searchsorted(self._ds.indices, item["index"]))

    def _packed_pass(self, take) -> dict[str, np.ndarray]:
        """One pass over the exported clips for the packed layout: ``take(name, rows)`` gets each
        clip's rows of each frame array (in the file's float type), in order; returns every
        other array of the layout (names, offsets, statistics...)."""
        self.check_one_skeleton("pack")
        ks = self.skeleton_ids()
        sk0 = self._ds.skeletons[ks[0]]
        dtype = np.result_type(*(self._attrs[k]["dtype"] for k in ks))
        names, roles, labels, fps, skel, joint_offsets, ends, lengths = [], [], [], [], [], [], [], []
        for item in self._items():
            k = int(item["skeleton"])
            for f in self.frame_arrays:
                take(f, np.ascontiguousarray(item[f].numpy().astype(dtype)))
            names.append(item["name"])
            roles.append(str(self._ds.table["role"][self._clip(item)]))
            labels.append(json.dumps(item["labels"], sort_keys=True))
            fps.append(item["fps"])
            skel.append(k)
            joint_offsets.append(self._ds.skeletons[k].offsets.numpy())
            ends.append(self._ds.skeletons[k])
            lengths.append(int(item["length"]))
        offsets = np.zeros(len(lengths) + 1, dtype=np.int64)
        offsets[1:] = np.cumsum(lengths)
        out = {"format": np.array(NPZ_FORMAT), "version": np.int64(NPZ_VERSION), "layout": np.array("packed"),
               **self._skeleton_arrays(ks[0]), "offsets": offsets,
               "names": np.array(names, dtype=str), "roles": np.array(roles, dtype=str),
               "labels": np.array(labels, dtype=str), "fps": np.array(fps, dtype=np.float64),
               "skeleton": np.array(skel, dtype=np.int64), "joint_offsets": np.stack(joint_offsets)}
        if all(s.end_site_parents == sk0.end_site_parents for s in ends):
            out["end_site_parents"] = np.array(sk0.end_site_parents, dtype=np.int64).reshape(-1)
            out["end_site_offsets"] = np.stack([s.end_site_offsets.numpy().reshape(-1, 3) for s in ends])
        out.update(self._stat_arrays())
        return out

    def packed(self) -> dict[str, np.ndarray]:
        """Every exported clip in the packed layout (one skeleton topology and unit, else a one-line
        error), in memory; :meth:`write_packed` writes the same file with memory flat in the clips."""
        frames: dict[str, list[np.ndarray]] = {f: [] for f in self.frame_arrays}
        out = self._packed_pass(lambda f, rows: frames[f].append(rows))
        for f, parts in frames.items():
            out[f] = np.concatenate(parts)
        return out

    def packed_frames(self) -> int:
        """Frames of the packed file (every exported clip's)."""
        return int(sum(int(self._ds._len[c]) for c in self._order))

    def write_packed(self, path) -> None:
        """Write :meth:`packed`'s file at ``path`` (straight there: the export stages it) with memory
        flat in the number of clips: one pass over the clips appends each frame array's rows to a
        file of its own beside ``path``, then the ``.npz`` (a zip of ``.npy`` members, as
        ``numpy.savez`` writes it) is assembled from them member by member. Values that are not
        finite are refused, naming the clip, before the file is complete."""
        path = Path(path)
        shapes: dict[str, tuple] = {}
        with tempfile.TemporaryDirectory(prefix=f".{path.name}.", dir=path.parent) as tmp:
            parts = {f: open(Path(tmp) / f"{f}.raw", "wb") for f in self.frame_arrays}

            def take(f, rows):
                shapes.setdefault(f, (rows.dtype, rows.shape[1:]))
                parts[f].write(rows.tobytes())

            try:
                small = self._packed_pass(take)
            finally:
                for f in parts.values():
                    f.close()
            total = int(small["offsets"][-1])
            with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_STORED, allowZip64=True) as zf:
                for key, a in small.items():
                    buf = io.BytesIO()
                    np.lib.format.write_array(buf, np.asanyarray(a), allow_pickle=False)
                    zf.writestr(f"{key}.npy", buf.getvalue())
                for f in self.frame_arrays:
                    dtype, tail = shapes[f]
                    header = {"descr": np.lib.format.dtype_to_descr(dtype), "fortran_order": False, "shape": (total, *tail)}
                    with zf.open(f"{f}.npy", "w", force_zip64=True) as member, open(Path(tmp) / f"{f}.raw", "rb") as raw:
                        np.lib.format.write_array_header_2_0(member, header)
                        shutil.copyfileobj(raw, member, 1 << 22)


def write_npz(path, arrays: dict[str, np.ndarray], what: str = "", atomic: bool = True) -> None:
    """Write ``arrays`` as an uncompressed ``.npz`` at ``path``, atomically (``atomic=False``:
    straight to ``path``, for a caller that stages its files already, like the exports).

    Every floating array must be finite: otherwise a one-line :class:`TorchspliceError` names
    ``what`` (e.g. the clip), the array and the first bad row, and nothing is written.
    """
    for key, a in arrays.items():
        a = np.asarray(a)
        if a.dtype.kind == "f" and not np.isfinite(a).all():
            row = int(np.flatnonzero(~np.isfinite(a.reshape(a.shape[0], -1)).all(axis=1))[0]) if a.ndim else 0
            raise TorchspliceError(f"{path}: {what + ': ' if what else ''}non-finite value in {key} "
                                   f"(row {row}); nothing written")
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    if not atomic:
        Path(path).write_bytes(buf.getbuffer())
        return
    with atomic_path(path) as tmp:
        Path(tmp).write_bytes(buf.getbuffer())


def read_npz(path) -> dict:
    """An exported ``.npz`` as a dict of numpy arrays; strings as ``str``, labels decoded from JSON
    (a dict, or for a packed file a list of dicts), scalars as Python numbers."""
    if not Path(path).is_file():
        raise TorchspliceError(f"{path}: no such file")
    try:
        z = np.load(path, allow_pickle=False)
        if not isinstance(z, np.lib.npyio.NpzFile):  # a .npy array
            raise ValueError("a single array, not an .npz archive")
        with z:
            out = {k: z[k] for k in z.files}
    except (OSError, ValueError, EOFError) as exc:  # not a .npz, or one with pickled objects (never loaded)
        raise TorchspliceError(f"{path}: not a torchsplice .npz export ({type(exc).__name__}: {exc})") from None
    if str(out.get("format", "")) != NPZ_FORMAT:
        raise TorchspliceError(f"{path}: not a torchsplice .npz export (no format {NPZ_FORMAT!r})")
    for k, v in list(out.items()):
        if v.ndim == 0:
            out[k] = v.item()
    if out["layout"] == "packed":
        out["labels"] = [json.loads(s) for s in out["labels"]]
    else:
        out["labels"] = json.loads(out["labels"])
    return out


def clip_of_packed(packed: dict, i: int) -> dict:
    """Clip ``i`` of a packed export (as :func:`read_npz` returns it): its frame arrays sliced by
    ``offsets``, with its ``name``, ``fps``, ``labels`` and ``joint_offsets``."""
    lo, hi = int(packed["offsets"][i]), int(packed["offsets"][i + 1])
    per_frame = (*FRAME_ARRAYS, *dict.fromkeys(f for fs in FEATURE_SETS.values() for f in fs))
    out = {k: packed[k][lo:hi] for k in per_frame if k in packed}
    out.update(name=str(packed["names"][i]), role=str(packed["roles"][i]), fps=float(packed["fps"][i]),
               labels=packed["labels"][i], joint_offsets=packed["joint_offsets"][i])
    return out
