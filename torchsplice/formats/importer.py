"""Importing BVH files into a motion database: the whole ``torchsplice import`` pipeline as one
function, :func:`import_bvh`, returning an :class:`ImportReport`.

    from torchsplice.formats.importer import import_bvh
    report = import_bvh(["path/to/bandai_namco/"], "bandai.h5", spec="bandai_namco")
    report.imported          # [ImportedClip(name, path, frames, windows), ...]
    report.skipped           # [(path, why), ...]: files that could not be used, the others landed
    report.guessed           # skeletons whose roles the ``generic`` spec guessed, with what it guessed

Folders are searched recursively for ``.bvh`` files; each file is read (lengths in the file's
units, quaternions WXYZ), checked, matched to a dataset spec (``spec="auto"``: per file), bound
to its skeleton, given its role and labels from its name, optionally cut into windows
(``window``), and appended. A file that cannot be used is skipped with a one-line reason; the
database is written atomically (appending works on a copy that replaces the file at the end).
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterable, Sequence

from ..core.errors import DatabaseError, TorchspliceError
from ..core.names import control_character, printable
from ..store.atomic import check_output
from .defaults import (DEFAULT_FILE_UNITS, DEFAULT_IMPORT_FORMAT, DEFAULT_IMPORT_WINDOW, DEFAULT_IMPORT_WINDOW_OVERLAP,
                       DEFAULT_NAME_PREFIX, DEFAULT_SPEC, DEFAULT_UNITS, IMPORT_FORMATS)
from .plain_files import not_regular

# torch, the specs, the units and the readers are imported where used: the command line reads
# DATABASE_SUFFIXES and one_line from this module before (or without) loading torch.

__all__ = ["import_bvh", "ImportOptions", "run_import", "ImportReport", "ImportedClip", "GuessedSkeleton", "NothingImportedError", "collect_bvh",
           "collect_inputs", "FORMATS"]

DATABASE_SUFFIXES = (".h5", ".hdf5")


@dataclass
class ImportedClip:
    """One imported file: its clip ``name`` (the file's stem), ``path``, ``frames`` and the
    ``windows`` it was cut into (1 when not cut)."""

    name: str
    path: str
    frames: int
    windows: int = 1


@dataclass
class GuessedSkeleton:
    """A new skeleton whose joint roles a guessing spec (``generic``) found: its id in the
    database, the file it was first seen in, the spec's name, and what was guessed
    (:meth:`~torchsplice.specs.DatasetSpec.guess_summary` lines; roles as a dict)."""

    skeleton: int
    path: str
    spec: str
    summary: list[str]
    roles: dict


@dataclass
class ImportReport:
    """What :func:`import_bvh` did.

    Attributes:
        output: the database written.
        imported: the files imported, in order.
        skipped: ``(path, why)`` of every input that could not be used (``why`` may start with
            ``LINE:`` for a BVH error).
        warnings: ``(path, message)`` of readable files with something odd (trailing lines).
        guessed: the skeletons whose roles were guessed.
        clips: clips in the database afterwards (all of them, when appending).
        window: the window length asked for (seconds), or ``None``.
    """

    output: Path
    imported: list[ImportedClip] = field(default_factory=list)
    skipped: list[tuple[str, str]] = field(default_factory=list)
    warnings: list[tuple[str, str]] = field(default_factory=list)
    guessed: list[GuessedSkeleton] = field(default_factory=list)
    clips: int = 0
    window: float | None = None

    @property
    def frames(self) -> int:
        """Frames imported (before cutting into windows)."""
        return sum(c.frames for c in self.imported)

    @property
    def cut(self) -> list[ImportedClip]:
        """The imported takes that were cut into windows."""
        return [c for c in self.imported if c.windows > 1]

    @property
    def ok(self) -> bool:
        """Whether every input was imported."""
        return not self.skipped


class NothingImportedError(TorchspliceError):
    """No clip could be imported; ``report`` says why for every input (nothing was written)."""

    def __init__(self, message: str, report: ImportReport):
        super().__init__(message)
        self.report = report


def _not_regular(path: Path) -> str:
    """Why a file that exists is not read (a named pipe, a device)."""
    return f"is {not_regular(path.stat().st_mode)}, not a regular file; not read"


def collect_bvh(paths: Iterable) -> tuple[list[Path], list[tuple[str, str]]]:
    """The ``.bvh`` files under ``paths`` (files, and folders searched recursively), each once,
    in order; and ``(path, why)`` for each path that holds none."""
    files, missing = [], []
    for p in map(Path, paths):
        if p.is_dir():
            named = sorted(f for f in p.rglob("*") if f.suffix.lower() == ".bvh" and not f.is_dir())
            found = [f for f in named if f.is_file()]
            missing += [(str(f), _not_regular(f)) for f in named if not f.is_file() and f.exists()]
            if not found:
                missing.append((str(p), "folder holds no .bvh files"))
            files += found
        elif p.is_file():
            files.append(p)
        elif p.exists():  # a named pipe or a device: reading it would block or never end
            missing.append((str(p), _not_regular(p)))
        else:
            missing.append((str(p), "no such file or folder"))
    seen, unique = set(), []
    for f in files:
        key = f.resolve()
        if key not in seen:
            seen.add(key)
            unique.append(f)
    return unique, missing


MIN_WINDOW_SECONDS = 1.0
"""The shortest window ``window`` cuts takes into (splicing needs at least a stride)."""


def one_line(message, path=None, limit: int = 300) -> str:
    """``message`` as one line of at most ``limit`` characters, without a leading ``PATH:``,
    control characters escaped (see :func:`~torchsplice.core.names.printable`)."""
    text = printable(" ".join(str(message).split()))
    if path is not None:
        text = text.removeprefix(f"{path}: ").removeprefix(f"{path}:").lstrip()
    return text if len(text) <= limit else text[:limit - 3] + "..."


FORMATS = IMPORT_FORMATS
"""What :func:`import_bvh` reads (declared in :mod:`.defaults`): ``auto`` takes a folder holding
``new_joint_vecs/`` as a HumanML3D folder and anything else as BVH."""


@dataclass(frozen=True)
class _HumanML3DItem:
    """One motion of a HumanML3D folder, to import."""

    folder: Path
    id: str
    split: str | None

    def __str__(self) -> str:
        return str(self.folder / "new_joint_vecs" / f"{self.id}.npy")


HUMANML3D_BATCH = 256
"""HumanML3D motions read and turned into rotations together by ``import``."""


class _HumanML3DReader:
    """The motions of ``items`` (:class:`_HumanML3DItem`), read :data:`HUMANML3D_BATCH` at a time
    as the import reaches them (:func:`~.humanml3d_import.read_humanml3d_motions`): :meth:`motion`
    gives an item's clip or raises what it met, each item once."""

    def __init__(self, items):
        self.items = list(items)
        self.place = {id(f): k for k, f in enumerate(self.items)}
        self.ready: dict[int, object] = {}

    def motion(self, item):
        from .humanml3d_import import read_humanml3d_motions

        k = self.place[id(item)]
        if k not in self.ready:
            batch = self.items[k:k + HUMANML3D_BATCH]
            got = read_humanml3d_motions([(f.folder, f.id, f.split) for f in batch])
            self.ready.update(zip(range(k, k + len(batch)), got))
        got = self.ready.pop(k)
        if isinstance(got, BaseException):
            raise got
        return got


def collect_inputs(paths: Iterable, format: str = "auto") -> tuple[list, list[tuple[str, str]]]:
    """What to import from ``paths``: BVH files (:func:`collect_bvh`) and the motions of HumanML3D
    folders (:mod:`.humanml3d_import`), in order; and ``(path, why)`` for what holds none."""
    from .humanml3d_import import humanml3d_ids, is_humanml3d_folder

    if format not in FORMATS:
        raise TorchspliceError(f"{{format}} must be one of {', '.join(FORMATS)}, got {format!r}", options=("format",))
    items, skipped, bvh = [], [], []
    for p in map(Path, paths):
        if format != "bvh" and is_humanml3d_folder(p):
            ids, split, missing = humanml3d_ids(p)
            skipped += missing
            items += [_HumanML3DItem(p, i, split.get(i)) for i in ids]
            if not ids:
                skipped.append((str(p), "HumanML3D folder holds no motions (new_joint_vecs/*.npy)"))
        elif format == "humanml3d":
            skipped.append((str(p), "not a HumanML3D folder (it holds no new_joint_vecs folder)"))
        else:
            bvh.append(p)
    files, missing = collect_bvh(bvh) if bvh else ([], [])
    return items + files, skipped + missing


def import_bvh(paths: Sequence, output, spec=DEFAULT_SPEC, append: bool = False, overwrite: bool = False,
               float64: bool = False, window: float | None = DEFAULT_IMPORT_WINDOW,
               window_overlap: float = DEFAULT_IMPORT_WINDOW_OVERLAP, units: str | None = DEFAULT_UNITS,
               progress: Callable | None = None, format: str = DEFAULT_IMPORT_FORMAT,
               file_units: str | None = DEFAULT_FILE_UNITS, name_prefix: str = DEFAULT_NAME_PREFIX) -> ImportReport:
    """Import BVH files and folders (and HumanML3D folders) into the database ``output`` (see
    the module docstring).

    Args:
        paths: files and folders (searched recursively for ``.bvh``); a HumanML3D folder (one
            holding ``new_joint_vecs/``) gives its motions on the SMPL body, with their captions
            (:mod:`.humanml3d_import`; ``spec`` does not apply to them: theirs is ``smpl22``).
        output: the database to write (``.h5`` or ``.hdf5``).
        spec: ``"auto"`` (a spec per file, :func:`~torchsplice.specs.detect_spec`), a shipped
            spec's name, a ``.toml`` path or a :class:`~torchsplice.specs.DatasetSpec`.
        append: add to the existing database ``output`` instead of making a new one.
        overwrite: replace an existing ``output`` (a new database only).
        float64: store frames in float64 (default float32).
        window: cut takes longer than 1.25 x ``window`` seconds into windows of ``window``
            seconds overlapping by ``window_overlap`` (named ``NAME#000``, ...; not a train/val/test
            split, which the exports and ``MotionDataset`` make by source clip).
        units: convert every clip's lengths from its spec's units to these (``"cm"``, ``"m"``,
            ... see :mod:`torchsplice.ops.units`), so that datasets share one database;
            ``None`` keeps the files' own units.
        file_units: the units the BVH files are in, where their spec does not say (``generic``,
            a guessed spec: units ``unknown``), so that they are recorded and ``units`` can
            convert them; a spec that names other units is refused for that file, in one line.
        progress: ``progress(iterable, total, desc) -> iterable`` to show progress (e.g. tqdm).
        name_prefix: put before every clip's name (``"h1_"`` for a second HumanML3D folder whose
            IDs are the first's, ``"cmu_"``), so that sources with the same file names share a
            database; labels that name a clip (``mirror_of``) get it too.
        format: ``"auto"`` (a HumanML3D folder as such, anything else as BVH), ``"bvh"`` or
            ``"humanml3d"`` (:data:`FORMATS`).

    Returns the :class:`ImportReport`. Raises :class:`NothingImportedError` (with the report)
    when no clip could be imported, and :class:`~torchsplice.core.errors.TorchspliceError` for
    a bad output or option; a full disk (:class:`~torchsplice.core.errors.DatabaseError`)
    stops the import with nothing written.
    """
    options = ImportOptions(output=output, spec=spec, append=append, overwrite=overwrite, float64=float64,
                            window=window, window_overlap=window_overlap, units=units, progress=progress,
                            format=format, file_units=file_units, name_prefix=name_prefix)
    return run_import(paths, options)


@dataclass
class ImportOptions:
    """What an import does with its inputs: :func:`import_bvh`'s arguments but ``paths`` (see
    there for each), as :func:`import_bvh` builds them for :func:`run_import`."""

    output: Path
    spec: object = DEFAULT_SPEC
    append: bool = False
    overwrite: bool = False
    float64: bool = False
    window: float | None = DEFAULT_IMPORT_WINDOW
    window_overlap: float = DEFAULT_IMPORT_WINDOW_OVERLAP
    units: str | None = DEFAULT_UNITS
    progress: Callable | None = None
    format: str = DEFAULT_IMPORT_FORMAT
    file_units: str | None = DEFAULT_FILE_UNITS
    name_prefix: str = DEFAULT_NAME_PREFIX


def run_import(paths: Sequence, options: ImportOptions) -> ImportReport:
    """The import of ``paths`` with ``options`` (see :func:`import_bvh`): the options checked, the
    inputs collected, the output checked, then each item loaded and appended, a failing one
    skipped with its reason."""
    o = options
    check_options(o)
    files, skipped = collect_inputs(paths, o.format)
    out = checked_output(o, files)
    report = ImportReport(output=out, skipped=skipped, window=o.window)
    if not files:
        raise NothingImportedError("no HumanML3D motions to import" if o.format == "humanml3d" else "no BVH files to import",
                                   report)
    check_window(o)
    import_items(files, out, o, report)
    return report


def check_options(o: ImportOptions) -> None:
    """The options that need no input checked before any work: the name prefix and the units."""
    from ..ops.units import CONVERTIBLE_UNITS, UNITS

    name_prefix, file_units, units = o.name_prefix, o.file_units, o.units
    bad = control_character(name_prefix) if name_prefix else ""
    if bad or not isinstance(name_prefix, str) or "," in name_prefix or ":" in name_prefix:
        raise TorchspliceError(f"{{name_prefix}} {name_prefix!r} must be text without control characters, commas or "
                               "colons (clip names are read by the selection language)", options=("name_prefix",))
    if file_units is not None and file_units not in CONVERTIBLE_UNITS:
        raise TorchspliceError(f"{{file_units}}: unknown length unit {file_units!r}; name one of "
                               f"{', '.join(CONVERTIBLE_UNITS)}", options=("file_units",))
    if units is not None and units not in CONVERTIBLE_UNITS:  # a known unit, checked before any work
        why = f"unknown length unit {units!r}" if units not in UNITS else f"cannot convert to {units!r} units"
        raise TorchspliceError(f"{{units}}: {why}; name a length unit ({', '.join(CONVERTIBLE_UNITS)})",
                               options=("units",))


def checked_output(o: ImportOptions, files: list) -> Path:
    """The database to write: an existing one to append to, or a new one that may be written
    (not one of the inputs; an existing file only with ``overwrite``)."""
    out = Path(o.output)
    if o.append:
        if out.suffix.lower() not in DATABASE_SUFFIXES:
            raise TorchspliceError(f"{out}: {{append}} adds to a database, so its name must end in .h5 or .hdf5",
                                   options=("append",))
        if not out.is_file():
            raise TorchspliceError(f"{out}: no such database to append to (leave out {{append}} to make a new one)",
                                   options=("append",))
        return out
    return check_output(out, DATABASE_SUFFIXES, "a database", inputs=[f for f in files if isinstance(f, Path)],
                        overwrite=o.overwrite)


def check_window(o: ImportOptions) -> None:
    """The window and its overlap, when takes are cut into windows."""
    window, window_overlap = o.window, o.window_overlap
    if window is not None and not (math.isfinite(window) and window >= MIN_WINDOW_SECONDS):
        raise TorchspliceError(f"{{window}} ({window:g} s) must be at least {MIN_WINDOW_SECONDS:g} s: a window is a clip "
                               "to splice", options=("window",))
    if window is not None and not 0 <= window_overlap < window:
        raise TorchspliceError(f"{{window_overlap}} ({window_overlap:g} s) must be at least 0 and shorter than "
                               f"{{window}} ({window:g} s)", options=("window_overlap", "window"))


def import_items(files: list, out: Path, o: ImportOptions, report: ImportReport) -> None:
    """Load and append every item of ``files`` to the database ``out`` (made, or opened to
    append), recording each in ``report``; a failing item is skipped with its reason, a failing
    output stops the import with nothing written."""
    import torch

    from ..specs import DatasetSpec, load_spec
    from ..store.database import MotionDatabase

    spec = o.spec
    fixed = None if isinstance(spec, str) and spec == "auto" else spec if isinstance(spec, DatasetSpec) else load_spec(spec)
    if o.append:
        db = MotionDatabase.open(out, mode="a")
    else:
        db = MotionDatabase.create(out, overwrite=o.overwrite, dtype="float64" if o.float64 else "float32")
    dtype = torch.float64 if o.float64 else torch.float32
    origin: dict[str, Path] = {}
    todo = o.progress(files, len(files), "import") if o.progress is not None else files
    humanml3d = _HumanML3DReader(f for f in files if isinstance(f, _HumanML3DItem))
    with db:
        for f in todo:
            try:
                m, s = load_item(f, o, fixed, dtype, humanml3d, report)
                pieces = append_clip(db, m, s, f, o, origin, report)
            except DatabaseError:
                raise  # the output itself failed (a full disk): nothing more can be written
            except TorchspliceError as exc:
                report.skipped.append((str(f), one_line(exc, f)))
                continue
            except (KeyboardInterrupt, MemoryError):
                raise
            except Exception as exc:  # a bug met on this file: skip it, keep the others, say what to report
                report.skipped.append((str(f), f"unexpected error ({type(exc).__name__}: {one_line(exc, f)}); "
                                               "please report it with the file"))
                continue
            origin[m.name] = f
            report.imported.append(ImportedClip(m.name, str(f), m.num_frames, pieces))
        if not report.imported:
            db.abort()
            raise NothingImportedError(f"no clip could be imported; {o.output} was not written", report)
        report.clips = len(db)


def load_item(f, o: ImportOptions, fixed, dtype, humanml3d: "_HumanML3DReader", report: ImportReport):
    """``(clip, its bound spec)`` of one input: a HumanML3D motion on the SMPL body, or a BVH file
    read, checked, matched to its spec (``fixed``, else detected) and given its role and labels;
    in ``o.units`` where given, its name prefixed. Warnings of the file go to ``report``."""
    from ..ops.units import convert_units
    from ..specs import detect_spec, load_spec
    from ..specs.smpl import SMPL22
    from .bvh import read_bvh

    units, file_units, name_prefix = o.units, o.file_units, o.name_prefix
    if isinstance(f, _HumanML3DItem):
        bad = control_character(f.id)
        if bad:
            raise TorchspliceError(f"clip name {f.id!r} (the file's name) contains {bad}; rename the file")
        m = humanml3d.motion(f).to(dtype)
        s = load_spec(SMPL22)
        if units is not None:
            m, s = convert_units(m, s, units)
    else:
        bad = control_character(f.stem)
        if bad:  # printed raw, such a name would drive the terminal
            raise TorchspliceError(f"clip name {f.stem!r} (the file's name) contains {bad}; rename the file")
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            m = read_bvh(f, dtype=dtype)
        report.warnings += [(str(f), one_line(w.message, f)) for w in caught]
        m.check_finite()
        s = (fixed or detect_spec(m.skeleton, f.name)).resolve(m.skeleton)
        if file_units is not None and s.units != file_units:
            if s.units != "unknown":
                raise TorchspliceError(f"its spec {s.name!r} says its units are {s.units!r}, not {file_units!r} "
                                       "(file_units is for specs that do not say)")
            s = dataclasses.replace(s, units=file_units)
        s.bind(m.skeleton)
        if units is not None:  # lengths in one unit, so that datasets share the database
            m, s = convert_units(m, s, units)
        m.role, m.labels = s.clip_metadata(m.name)
    if name_prefix:
        m.name = name_prefix + m.name
        if "mirror_of" in m.labels:
            m.labels["mirror_of"] = name_prefix + m.labels["mirror_of"]
    return m, s


def append_clip(db, m, s, f, o: ImportOptions, origin: dict, report: ImportReport) -> int:
    """Append clip ``m`` (spec ``s``, from input ``f``) to ``db``, cut into windows where asked;
    the number of pieces. A name imported before (``origin``: name to input) or already in the
    database is refused; a new skeleton's guessed roles and implausible size go to ``report``."""
    from ..ops.units import implausible_size

    window, window_overlap = o.window, o.window_overlap
    if m.name in origin:
        raise TorchspliceError(f"clip name {m.name!r} already imported from {origin[m.name]}")
    pieces = m.windows(window, window_overlap) if window else [m]
    taken = [p.name for p in pieces if p.name in db]
    if taken:  # appending: this file is skipped, the others land
        raise TorchspliceError(f"clip name {taken[0]!r} is already in the database")
    known = len(db.skeletons)
    for piece in pieces:
        db.append(piece, spec=s)
    if len(db.skeletons) > known and s.is_guessed:
        report.guessed.append(GuessedSkeleton(known, str(f), s.name, s.guess_summary(), s.guessed_roles()))
    if len(db.skeletons) > known and (odd := implausible_size(m.skeleton, s.units)):  # once a skeleton
        report.warnings.append((str(f), odd))
    return len(pieces)
