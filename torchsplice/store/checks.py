"""Checking a database file's structure when it is opened, without reading its frames.

Shapes and dtypes of every dataset, attributes, JSON, and the clip table's index ranges, all
vectorised (a 100,000-clip file opens in milliseconds): :func:`check_header` raises one
:class:`~torchsplice.core.errors.DatabaseError` line naming the file and its first problem.
Damaged frames are found by the reads that meet them (see :mod:`torchsplice.store.reading`).
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import h5py
import numpy as np

from ..core.errors import DatabaseError
from ..core.names import CONTROL, control_character, printable
from ..core.skeleton import Skeleton
from .assembly import (
    ALIGNMENT,
    BANKS,
    FRAME_PARTS,
    KIND_CODES,
    MOTION,
    OPTIONAL_PARTS,
    PART_COLUMNS,
    STORES,
    bank_tables,
    store_kind,
)
from .schema import (
    CLIPS,
    COMPRESSIONS,
    FORMAT,
    SCHEMA_VERSION,
    SKELETONS,
    Damage,
    cap,
    checked_dataset,
    extra_columns,
    first_non_finite_row,
    short,
    skeleton_from_group,
    skeleton_path,
    text_attr,
)

__all__ = [
    "check_header",
    "check_structure",
    "check_store_kind",
    "check_banks",
    "check_assembly",
    "unreadable_bank",
    "control_name",
    "whole_number",
]


def whole_number(v) -> int | None:
    """An attribute's value as an int, or ``None`` when it is not one whole number."""
    if isinstance(v, bytes):
        v = v.decode(errors="replace")
    if isinstance(v, str):
        v = v.strip()
        return int(v) if v.lstrip("+-").isdigit() and v.isascii() else None
    if np.ndim(v) != 0 or isinstance(v, (bool, np.bool_)):
        return None
    if isinstance(v, (int, np.integer)):
        return int(v)
    if isinstance(v, (float, np.floating)) and float(v).is_integer():
        return int(v)
    return None


def check_structure(h5: h5py.File, mode: str) -> list[Skeleton]:
    """Check a database's structure without reading its frames; returns its skeletons.

    Shapes and dtypes of every dataset, attributes, JSON, and the clip table's index ranges
    (vectorised: a 100,000-clip file opens in milliseconds). Raises :class:`Damage` naming
    the first problem.
    """
    check_store_kind(h5)
    if mode == "a":
        if (whole_number(h5.attrs.get("chunk_frames")) or 0) < 1:
            raise Damage(f"chunk_frames is not a positive whole number ({cap(h5.attrs.get('chunk_frames'))})")
        comp = text_attr(h5.attrs, "compression", "")
        if comp and comp not in COMPRESSIONS:
            raise Damage(f"compression {cap(comp)} is not one of {', '.join(c for c in COMPRESSIONS if c)}")
    columns, frame_columns = extra_columns(h5.attrs)
    for group in (SKELETONS, CLIPS):
        if not isinstance(h5.get(group), h5py.Group):
            raise Damage(f"the {group} group is missing")
    keys = list(h5[SKELETONS])
    if sorted(keys, key=lambda k: (len(k), k)) != [str(k) for k in range(len(keys))]:
        raise Damage(f"skeletons holds {cap(', '.join(keys))}, expected groups 0..{len(keys) - 1}")
    skeletons, frames = [], []
    for k in range(len(keys)):
        where = skeleton_path(k)
        g = h5[where]
        if not isinstance(g, h5py.Group):
            raise Damage(f"{where} is not a group")
        sk = skeleton_from_group(g, where)
        spec = text_attr(g.attrs, "spec", f"{where} ")
        if spec.strip():
            try:
                ok = isinstance(json.loads(spec), dict)
            except ValueError:
                ok = False
            if not ok:
                raise Damage(f"{where} spec is not valid JSON ({cap(spec)})")
        J = sk.num_joints
        rot = checked_dataset(g, "rotations", where, (None, J, 4), "f")
        N = rot.shape[0]
        if rot.is_virtual and not os.environ.get("HDF5_VDS_PREFIX"):  # a missing source reads as NaN, silently
            folder = Path(h5.filename).resolve().parent
            for src in sorted({vs.file_name for vs in rot.virtual_sources()} - {"."}):
                if not (folder / src).is_file():
                    raise Damage(
                        f"the frames of {where} are in {cap(src, 80)}, which is missing "
                        "(keep the shards folder beside the database)"
                    )
        checked_dataset(g, "root_translation", where, (N, 3), "f")
        if "translations" in g or sk.has_joint_translations:
            checked_dataset(g, "translations", where, (N, J, 3), "f")
        for name in frame_columns:
            checked_dataset(g, name, where, (N,), "f")
        skeletons.append(sk)
        frames.append(N)
    c = h5[CLIPS]
    C = checked_dataset(c, "name", "clips", (None,), "str").shape[0]
    kinds = {"str": "str", "int": "iu", "float": "fiu"}
    for name, kind in [
        ("name", "str"),
        ("source", "str"),
        ("role", "str"),
        ("labels", "str"),
        ("skeleton", "int"),
        ("start", "int"),
        ("length", "int"),
        ("fps", "float"),
        *columns.items(),
    ]:
        ds = checked_dataset(c, name, "clips", (None,), kinds[kind])
        if ds.shape[0] != C:
            raise Damage(f"clips/{name} has {ds.shape[0]} rows, clips/name {C}")
    if C == 0:
        if store_kind(h5.attrs) == ALIGNMENT:
            check_assembly(h5, skeletons, frames)
        return skeletons
    sk, start, length, fps = (c[n][()] for n in ("skeleton", "start", "length", "fps"))

    def clip(i: int) -> str:
        try:
            return f"clip {cap(c['name'].asstr()[i])}"
        except (OSError, ValueError):
            return f"clip row {i}"

    def first(bad: np.ndarray) -> int | None:
        hits = np.flatnonzero(bad)
        return int(hits[0]) if hits.size else None

    K = len(skeletons)
    if (i := first((sk < 0) | (sk >= K))) is not None:
        have = (
            f"the file has skeletons 0..{K - 1}"
            if K > 1
            else "the file has only skeleton 0"
            if K
            else "the file has none"
        )
        raise Damage(f"{clip(i)} points at skeleton {int(sk[i])}; {have}")
    if (i := first(start < 0)) is not None:
        raise Damage(f"{clip(i)} starts at row {int(start[i])} of skeleton {int(sk[i])}")
    if (i := first(length < 0)) is not None:
        raise Damage(f"{clip(i)} has {int(length[i])} frames")
    rows = np.asarray(frames, dtype=np.int64)[sk.astype(np.int64)]
    if (i := first(start.astype(np.int64) + length.astype(np.int64) > rows)) is not None:
        raise Damage(
            f"{clip(i)} ends at row {int(start[i]) + int(length[i])} of skeleton {int(sk[i])}, "
            f"which has {int(rows[i])} frames"
        )
    if (i := first(~(np.isfinite(fps) & (fps > 0)))) is not None:
        raise Damage(f"{clip(i)} has fps {float(fps[i]):g}")
    names = c["name"].asstr()
    for lo in range(0, len(fps), NAME_BLOCK):  # a block at a time: millions of names never sit in memory at once
        bad = control_name(names[lo : lo + NAME_BLOCK], first_row=lo)
        if bad is not None:
            raise Damage(bad)
    if store_kind(h5.attrs) == ALIGNMENT:
        check_assembly(h5, skeletons, frames)
    return skeletons


NAME_BLOCK = 1 << 16
"""Clip names a check of a database's names reads at a time."""


def control_name(names, first_row: int = 0) -> str | None:
    """What is wrong with the first of ``names`` (rows ``first_row`` on) that holds a control
    character (see :mod:`torchsplice.core.names`), or ``None``; fast when none does."""
    names = [str(n) for n in names]
    if not CONTROL.search("".join(names)):
        return None
    row, name = next((k, n) for k, n in enumerate(names) if CONTROL.search(n))
    return f"clip name {cap(printable(name))} (row {first_row + row}) contains {control_character(name)}"


def check_header(path: Path, h5: h5py.File, mode: str = "r") -> list[Skeleton]:
    """Check the file's format, version and structure (see :func:`check_structure`); returns
    its skeletons, or raises one :class:`DatabaseError` line naming the file and the first problem."""
    fmt = h5.attrs.get("format")
    if not isinstance(fmt, (str, bytes)) or (fmt.decode(errors="replace") if isinstance(fmt, bytes) else fmt) != FORMAT:
        raise DatabaseError(f"{path}: not a torchsplice motion database (no format attribute {FORMAT!r})")
    raw = h5.attrs.get("schema_version")
    version = whole_number(raw) if raw is not None else None
    if version is None:
        have = "no schema_version attribute" if raw is None else f"schema_version is not a whole number ({cap(raw)})"
        raise DatabaseError(f"{path}: damaged database: {have}")
    if version > SCHEMA_VERSION:
        raise DatabaseError(
            f"{path}: schema version {version} is newer than this torchsplice reads ({SCHEMA_VERSION}); upgrade torchsplice"
        )
    if version < 1:
        raise DatabaseError(f"{path}: damaged database: schema version {version}")
    try:
        return check_structure(h5, mode)
    except Damage as exc:
        raise DatabaseError(f"{path}: damaged database: {exc}") from None
    except (OSError, KeyError, TypeError, ValueError, IndexError, AttributeError, RuntimeError) as exc:
        raise DatabaseError(f"{path}: damaged database: cannot read its structure ({short(exc)})") from None


def check_store_kind(h5: h5py.File) -> None:
    """The root ``store`` attribute against the layout: an unknown kind, or a file that holds an
    alignment store's source clips (``assembly/banks``) or all its clip parts (``assembly_*`` columns)
    while its attribute says (or, deleted, defaults to) ``motion``, whose frame datasets would
    read as the zeros never written; raises :class:`Damage`."""
    raw = h5.attrs.get("store")
    kind = store_kind(h5.attrs)
    if kind not in STORES:
        raise Damage(f"its store attribute is {cap(raw)}, neither {' nor '.join(STORES)}")
    if kind != MOTION:
        return
    clips = h5.get(CLIPS)
    parts = isinstance(clips, h5py.Group) and all(n in clips for n in PART_COLUMNS)
    if BANKS in h5 or parts:
        held = BANKS if BANKS in h5 else "clip parts (clips/assembly_*)"
        said = "is missing" if raw is None else f"says {cap(raw)}"
        raise Damage(
            f"it holds an alignment store's {held} but its store attribute {said} (an alignment store's "
            "says 'alignment'; as a motion store its spliced clips would read as zeros)"
        )


def check_banks(path, h5: h5py.File, banks: list[dict]) -> None:
    """An alignment store's source banks as read (``banks``: :attr:`~.assembly.Assembly.banks`,
    float64), checked once per read of them: a value that is not finite (a damaged chunk that
    still decompresses, a row overwritten) is one :class:`DatabaseError` line naming the file, the
    bank and the source clip, so that no motion is assembled from it (:func:`~.schema.first_non_finite_row`)."""
    for b, bank in enumerate(banks):
        for name, key in (("rotations", "rot"), ("translations", "trans")):
            bad = first_non_finite_row(bank[key])
            if bad is not None:
                raise DatabaseError(
                    f"{path}: damaged alignment store: bank {b} ({BANKS}/{b}) holds non-finite {name} "
                    f"in {_bank_clip(h5[f'{BANKS}/{b}'], bad, frame=True)}"
                )


def unreadable_bank(path, h5: h5py.File, exc: BaseException) -> str:
    """The line that says which source bank of an alignment store cannot be read (a chunk that does
    not decompress), from where (its first such chunk's rows and source clip); ``exc`` said where
    no bank is to blame."""
    for b in range(len(h5[BANKS])):
        g = h5[f"{BANKS}/{b}"]
        for name in ("rotations", "translations"):
            ds = g[name]
            step = max(ds.chunks[0] if ds.chunks else len(ds), 1)
            for lo in range(0, len(ds), step):
                try:
                    ds[lo : lo + step]
                except (OSError, ValueError, RuntimeError) as why:
                    return (
                        f"{path}: damaged alignment store: bank {b} ({BANKS}/{b}) cannot be read from "
                        f"{_bank_clip(g, lo)} on (rows {lo}:{min(lo + step, len(ds))} of its {name}: {short(why, 80)})"
                    )
    return f"{path}: damaged alignment store: its parts cannot be read ({short(exc, 80)})"


def _bank_clip(g: h5py.Group, row: int, frame: bool = False) -> str:
    """The source clip of bank ``g`` that holds ``row`` (and, with ``frame``, its frame there), in words."""
    try:
        starts, lengths = g["starts"][()].astype(np.int64), g["lengths"][()].astype(np.int64)
        c = int(np.searchsorted(starts, row, side="right")) - 1
        if 0 <= c < len(starts) and row < starts[c] + lengths[c]:
            return f"source clip {cap(g['names'].asstr()[c])}" + (
                f" at its frame {row - int(starts[c])}" if frame else ""
            )
    except (OSError, ValueError, KeyError, TypeError):
        pass
    return f"row {row}"


def check_assembly(h5: h5py.File, skeletons: list, frames: list[int]) -> None:
    """Check an alignment store's banks, parts and the clips' references into them (vectorised);
    raises :class:`Damage` naming the first problem."""
    banks = h5.get(BANKS)
    if not isinstance(banks, h5py.Group):
        raise Damage("it is an alignment store without its source clips (assembly/banks is missing)")
    keys = list(banks)
    if sorted(keys, key=lambda k: (len(k), k)) != [str(b) for b in range(len(keys))]:
        raise Damage(f"assembly/banks holds {cap(', '.join(keys))}, expected groups 0..{len(keys) - 1}")
    sizes, counts, joints = [], [], []
    for b in range(len(keys)):
        where = f"{BANKS}/{b}"
        g = banks[str(b)]
        if not isinstance(g, h5py.Group):
            raise Damage(f"{where} is not a group")
        rot = checked_dataset(g, "rotations", where, (None, None, 4), "f")
        N, J = rot.shape[0], rot.shape[1]
        checked_dataset(g, "translations", where, (N, J, 3), "f")
        C = checked_dataset(g, "starts", where, (None,), "iu").shape[0]
        for name, kind in (("lengths", "iu"), ("names", "str"), ("keys", "str"), ("fps", "fiu")):
            checked_dataset(g, name, where, (C,), kind)
        starts, lengths = g["starts"][()].astype(np.int64), g["lengths"][()].astype(np.int64)
        if C and ((starts < 0).any() or (lengths < 1).any() or (starts + lengths > N).any()):
            raise Damage(f"{where} has source clips outside its {N} frames")
        try:
            tables = json.loads(g.attrs.get("tables", ""))
            bank_tables(tables, J)
        except (ValueError, TypeError, KeyError, IndexError) as exc:
            raise Damage(f"{where} has no valid joint tables ({cap(str(exc), 60)})") from None
        sizes.append(lengths)
        counts.append(C)
        joints.append(J)
    for k, N in enumerate(frames[: len(skeletons)]):
        g = h5[skeleton_path(k)]
        for name, (shape, _) in FRAME_PARTS.items():
            if name in g or name not in OPTIONAL_PARTS:
                checked_dataset(g, name, skeleton_path(k), (N, *shape), "f")
    c = h5[CLIPS]
    if c["name"].shape[0] == 0:
        return
    p = {n: c[n][()].astype(np.int64) for n in PART_COLUMNS}
    sk = c["skeleton"][()].astype(np.int64)
    kind, bank = p["assembly_kind"], p["assembly_bank"]
    bad = ~np.isin(kind, list(KIND_CODES.values()))
    parts = kind > 0
    bad |= parts & ((bank < 0) | (bank >= len(keys)))
    if not bad.any() and parts.any():
        C = np.array(counts, np.int64)[np.where(parts, bank, 0)]
        J = np.array(joints, np.int64)[np.where(parts, bank, 0)]
        lo, ac = p["assembly_locomotion"], p["assembly_action"]
        bad |= parts & ((lo < 0) | (lo >= C) | (ac < 0) | (ac >= C))
        bad |= parts & (J != np.array([s.num_joints for s in skeletons], np.int64)[sk])
        if not bad.any():
            length = c["length"][()].astype(np.int64)
            la = np.zeros(len(kind), np.int64)
            aa = np.zeros(len(kind), np.int64)
            for b in range(len(keys)):
                m = parts & (bank == b)
                la[m], aa[m] = sizes[b][lo[m]], sizes[b][ac[m]]
            bad |= parts & ((length > la) | (p["assembly_crop"] < 0) | (p["assembly_crop"] >= np.maximum(aa, 1)))
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise Damage(
            f"clip {cap(c['name'].asstr()[i])}'s parts do not fit the alignment store's source clips "
            f"(kind {int(kind[i])}, bank {int(bank[i])})"
        )
