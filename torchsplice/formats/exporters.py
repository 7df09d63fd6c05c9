"""Export formats as plug-ins: one :class:`Exporter` per format, in a registry, and one
function, :func:`export_clips`, that writes clips of a database in any of them, all or nothing.

An exporter is a format's name (what users type: ``torchsplice export --format NAME``,
``export_clips(..., format=NAME)``), the suffix of its files, and a method that writes one
clip (a :class:`~torchsplice.core.motion.Motion`, float64) to a path. What every export shares
is done once, here, whatever the format: choosing the clips (names in the order given, or every
clip, kept to some skeletons), naming their files (safe on every system and unique without
regard to case, :func:`clip_filenames`), checking the output before any work (a file for one
clip or a packed file, else a folder), and writing every file under a hidden name and
installing them all or none (:mod:`.staging`). So a new format is one module::

    from torchsplice.formats.exporters import Exporter, register_exporter

    class RootCSV(Exporter):
        name, suffix = "rootcsv", ".csv"
        what, title = "a CSV file", "root CSV"       # in messages: "must end in .csv", "3 clips as root CSV"

        def write(self, motion, path):             # motion: a Motion (float64); path: where to write it
            rows = motion.root_translation.tolist()
            path.write_text("".join(f"{x},{y},{z}\\n" for x, y, z in rows))

    register_exporter(RootCSV)

loaded as plug-in methods are (``--plugin MODULE``, ``TORCHSPLICE_PLUGINS``, or the
``torchsplice.methods`` entry point group: see :mod:`torchsplice.splice.registry`). A format
that needs more than one clip at a time (statistics over every clip, one packed file) overrides
:meth:`Exporter.select`, :meth:`Exporter.check`, :meth:`Exporter.items` and
:attr:`Exporter.single_file`, as the NumPy exporter does (:mod:`.npz_exporter`). Options a
format takes (``packed``, ``features``) are declared in :attr:`Exporter.options`, each an
:class:`~.defaults.ExportOption` (its default, allowed values, type and help): keywords of
:func:`export_clips`, and the ``export`` command's flags (``--packed``, ``--features``), a
plug-in format's as the built-ins'. The built-ins, ``bvh`` (:mod:`.bvh_exporter`) and ``npz`` (:mod:`.npz_exporter`), register
themselves on first use of the registry. This module imports no torch, numpy or h5py: the
command line lists the formats without loading them.
"""

from __future__ import annotations

import hashlib
import importlib
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar, Iterable, Iterator, Sequence

from ..core.errors import TorchspliceError, render_message
from ..core.names import counted, printable
from ..data.splits import parse_ratios, parse_seed
from ..store.atomic import check_output, os_error_message
from .defaults import DEFAULT_EXPORT_INDEX, DEFAULT_FORMAT, ExportOption
from .index import index_files, index_targets
from .staging import staged_files

if TYPE_CHECKING:  # pragma: no cover
    from ..store.database import MotionDatabase

__all__ = ["Exporter", "selected_names", "ExportOption", "ExportResult", "register_exporter", "get_exporter", "available_exporters",
           "choose_exporter", "export_clips", "export_targets", "folder_targets", "select_rows", "clip_filename", "clip_filenames",
           "MAX_FILE_BYTES", "DEFAULT_FORMAT"]

_BUILTIN_MODULES = ("torchsplice.formats.bvh_exporter", "torchsplice.formats.npz_exporter",
                    "torchsplice.formats.humanml3d_exporter")
_EXPORT_KEYWORDS = ("database", "clips", "out", "format", "overwrite", "skeletons", "command", "select", "index", "progress")
_NAME = re.compile(r"^[a-z][a-z0-9_-]*$")
_SUFFIX = re.compile(r"^\.[A-Za-z0-9][A-Za-z0-9_-]*$")
READ_BATCH = 64
"""Clips read from the database at a time by :meth:`Exporter.items`."""
SHARED_OPTIONS = ("split_ratios", "split_seed")
"""Options of every export: the splits of its index (:mod:`.index`; a format that writes its own
splits, as HumanML3D's does, declares them too and gets them)."""


@dataclass
class ExportResult:
    """What :func:`export_clips` wrote.

    Attributes:
        format: the format's name.
        output: the output as given (a file, or the folder of the clips' files).
        files: the files written, in export order (one for a packed file).
        names: the exported clips, in export order.
        frames: frames written in all.
        fps: the frame rate of each clip written as a file of its own (empty for a packed file).
        summary: one line saying what was written (``"OUT: 3 clips as BVH, 900 frames"``).
        summary_text, summary_options: ``summary`` with the options it names as ``{option}`` (said as flags by the CLI).
        index_files: the index and split lists written beside the clips (:mod:`.index`; empty
            for one clip, without ``index``, or for a format with a layout of its own).
    """

    format: str
    output: Any
    files: list[Path]
    names: list[str]
    frames: int = 0
    fps: list[float] = field(default_factory=list)
    summary: str = ""
    index_files: list[Path] = field(default_factory=list)
    summary_options: tuple[str, ...] = ()
    summary_text: str = ""


class Exporter:
    """One export format (see the module docstring); an instance is one export.

    Class attributes:
        name: what users type (``--format NAME``): lower case letters, digits, ``_`` and ``-``.
        suffix: the suffix of its files (``".bvh"``).
        what: a file of the format, in messages (``"BVH"``: "the output is BVH, so its name must end in .bvh").
        title: the format in summaries (``"BVH"``: "3 clips as BVH").
        options: the keyword options it takes, with their defaults and choices.
        summary_options: the options its :meth:`summary` may name, written ``{option}`` there.

    An instance holds the export's ``database``, ``clips`` (names, or ``None`` for every clip),
    ``skeletons`` (database skeleton ids to keep, or ``None``) and ``options`` (every declared
    option, defaults filled in).
    """

    name: ClassVar[str] = ""
    suffix: ClassVar[str] = ""
    what: ClassVar[str] = ""
    title: ClassVar[str] = ""
    options: ClassVar[dict[str, ExportOption]] = {}
    summary_options: ClassVar[tuple[str, ...]] = ()

    def __init__(self, database, clips: Sequence[str] | None = None, skeletons: Sequence[int] | None = None,
                 **options):
        self.database = Path(database)
        self.clips = None if clips is None else list(clips)
        self.skeletons = None if skeletons is None else list(skeletons)
        declared = type(self).options
        unknown = sorted(set(options) - set(declared))
        if unknown:
            raise TorchspliceError(f"format {self.name!r} takes no option {unknown[0]!r}"
                                   + (f" (it takes {', '.join(declared)})" if declared else ""))
        self.options = {k: o.default for k, o in declared.items()}
        self.options.update({k: v for k, v in options.items() if v is not None})  # None: the default
        for k, o in declared.items():
            if o.choices is not None and self.options[k] != o.default and self.options[k] not in o.choices:
                raise TorchspliceError(f"{{{k}}} must be one of {', '.join(map(str, o.choices))}, got {self.options[k]!r}",
                                       options=(k,))
        self._names: list[str] | None = None

    # -- what a format may override -----------------------------------------------------------
    @property
    def names(self) -> list[str]:
        """The exported clips' names, in export order (chosen on first use, by :meth:`select`)."""
        if self._names is None:
            self._names = list(self.select())
        return self._names

    def select(self) -> list[str]:
        """The clips to export (one-line errors for an unknown clip or skeleton, or none left)."""
        from ..store.database import MotionDatabase  # h5py and torch: imported where used (module docstring)

        with MotionDatabase.open(self.database) as db:
            names = db.names
            return [names[r] for r in select_rows(db, self.clips, self.skeletons)]

    @property
    def single_file(self) -> bool:
        """Every clip goes to one file (a packed file), whatever their number."""
        return False

    def layout(self) -> list[str] | None:
        """A folder format's files: their paths inside the output folder (``/``-separated,
        subfolders allowed), in the order :meth:`items` yields what :meth:`write` writes to
        them; ``None`` (the default) for one file per clip, named after it. A format whose
        export is a folder of several kinds of file (a dataset's layout: per-clip files in
        subfolders, statistics, split lists) overrides it, as :mod:`.humanml3d_exporter` does."""
        return None

    def owned(self, folder: Path) -> list[Path]:
        """A folder format's files an earlier torchsplice export of it left in ``folder`` (its
        per-clip files, as that export's own record lists them): an export that overwrites
        removes those it did not write again, once it is installed. Never a file that no
        torchsplice export wrote."""
        return []

    def foreign(self, folder: Path) -> str | None:
        """Why ``folder`` must not be overwritten by this folder format: it holds the format's
        files but no earlier torchsplice export wrote them (a dataset of the format from
        elsewhere, which ``overwrite`` would destroy); ``None`` when it may be."""
        return None

    def check(self) -> None:
        """What must hold before any file is made (e.g. statistics over every clip); one-line errors."""

    def items(self) -> Iterator[Any]:
        """What :meth:`write` takes, one per file, in export order: by default each clip as a
        :class:`~torchsplice.core.motion.Motion` (float64), read :data:`READ_BATCH` at a time."""
        import torch  # torch and h5py: imported where used (module docstring)

        from ..store.database import MotionDatabase

        names = self.names
        with MotionDatabase.open(self.database) as db:
            for b in range(0, len(names), READ_BATCH):
                yield from db.read_many(names[b:b + READ_BATCH], dtype=torch.float64)

    def measure(self, item) -> tuple[int, float | None]:
        """``(frames, fps)`` of an item (``fps`` ``None`` for a packed file)."""
        return int(item.num_frames), float(item.fps)

    def write(self, item, path: Path) -> None:
        """Write one item (a clip) as a file at ``path``."""
        raise NotImplementedError

    def summary(self, result: ExportResult) -> str:
        """One line saying what ``result`` holds (the command line prints it after ``wrote``)."""
        if len(result.names) == 1 and len(result.files) == 1 and result.fps:
            return f"{result.files[0]}: {result.names[0]}, {result.frames} frames at {result.fps[0]:g} fps"
        return f"{result.output}: {counted(len(result.names), 'clip')} as {self.title}, {result.frames} frames"


# --------------------------------------------------------------------------------------------
# the registry
# --------------------------------------------------------------------------------------------
_REGISTRY: dict[str, type[Exporter]] = {}
_LOADED = [False]


def register_exporter(exporter: type[Exporter], replace_existing: bool = False) -> type[Exporter]:
    """Add the format ``exporter`` (an :class:`Exporter` subclass) to the registry and return it.

    Raises :class:`~torchsplice.core.errors.TorchspliceError` for a malformed name or suffix, a
    class that writes nothing, or a name already taken by another format (unless
    ``replace_existing``). Registering the same class again (a module imported twice) is harmless.
    """
    _ensure_builtins()
    if not (isinstance(exporter, type) and issubclass(exporter, Exporter)):
        raise TorchspliceError("register_exporter takes a subclass of torchsplice.formats.exporters.Exporter, "
                               f"got {type(exporter).__name__}")
    name = exporter.name
    if not isinstance(name, str) or not _NAME.fullmatch(name):
        raise TorchspliceError(f"format name {name!r} must be lower case letters, digits, '_' or '-', "
                               "starting with a letter")
    if not isinstance(exporter.suffix, str) or not _SUFFIX.fullmatch(exporter.suffix):
        raise TorchspliceError(f"format {name!r}: suffix {exporter.suffix!r} must be a dot and letters or digits, "
                               "such as '.csv'")
    if exporter.write is Exporter.write:
        raise TorchspliceError(f"format {name!r}: the exporter must define write(item, path)")
    if not isinstance(exporter.options, dict) or not all(isinstance(o, ExportOption) for o in exporter.options.values()):
        raise TorchspliceError(f"format {name!r}: options must map names to ExportOption")
    taken = [k for k in exporter.options if not (isinstance(k, str) and k.isidentifier()) or k in _EXPORT_KEYWORDS]
    if taken:
        raise TorchspliceError(f"format {name!r}: option name {taken[0]!r} is not a name or is export_clips's own")
    exporter.what = exporter.what or f"a {exporter.suffix} file"
    exporter.title = exporter.title or name
    old = _REGISTRY.get(name)
    if old is not None and old is not exporter and not replace_existing and (old.__module__, old.__qualname__) != (
            exporter.__module__, exporter.__qualname__):
        raise TorchspliceError(f"format {name!r} is already registered (by {old.__module__}); choose another name")
    _REGISTRY[name] = exporter
    return exporter


def _ensure_builtins() -> None:
    if not _LOADED[0]:
        _LOADED[0] = True
        for module in _BUILTIN_MODULES:
            importlib.import_module(module)


def get_exporter(name: str) -> type[Exporter]:
    """The registered format called ``name``; a clear error naming the formats otherwise."""
    _ensure_builtins()
    exporter = _REGISTRY.get(name)
    if exporter is None:
        raise TorchspliceError(f"unknown export format {name!r}; choose one of {', '.join(available_exporters())}")
    return exporter


def available_exporters() -> tuple[str, ...]:
    """The registered formats' names: the built-ins first, then plug-ins in the order they registered."""
    _ensure_builtins()
    return tuple(_REGISTRY)


def choose_exporter(format: str | None, output, options: dict) -> type[Exporter]:
    """The format of an export: ``format`` if given; else the first format that takes every
    option given (not ``None`` or ``False``), else the one whose suffix ``output`` has, else
    :data:`DEFAULT_FORMAT`. An option the format does not take is refused in one line."""
    _ensure_builtins()
    unknown = sorted(k for k in options if k not in SHARED_OPTIONS and not any(k in e.options for e in _REGISTRY.values()))
    if unknown:
        taken = sorted({k for e in _REGISTRY.values() for k in e.options} | set(SHARED_OPTIONS))
        raise TorchspliceError(f"unknown export option {unknown[0]!r}; the formats take {', '.join(taken) or 'none'}")
    given = [k for k, v in options.items() if v is not None and v is not False and k not in SHARED_OPTIONS]
    if format is None:
        takers = [n for n, e in _REGISTRY.items() if all(k in e.options for k in given)] if given else []
        suffix = Path(output).suffix.lower()
        by_suffix = [n for n, e in _REGISTRY.items() if e.suffix.lower() == suffix]
        format = takers[0] if takers else by_suffix[0] if by_suffix else DEFAULT_FORMAT
    exporter = get_exporter(format)
    for k in given:
        if k not in exporter.options:
            takers = [n for n, e in _REGISTRY.items() if k in e.options]
            raise TorchspliceError(f"{{{k}}} needs {{format}} {' or '.join(takers)} ({exporter.title} holds one clip "
                                   "per file)", options=(k, "format"))
    return exporter


# --------------------------------------------------------------------------------------------
# the export
# --------------------------------------------------------------------------------------------
def export_clips(database, clips: Sequence[str] | None = None, *, out, format: str | None = None,
                 overwrite: bool = False, skeletons: Iterable[int] | None = None, command: str = "",
                 select: str | Sequence[str] | None = None, index: bool = DEFAULT_EXPORT_INDEX, progress=None,
                 **options) -> ExportResult:
    """Write clips of a database as files of a registered format, all or nothing.

    Args:
        database: the motion database.
        clips: clip names, in the order wanted (repeats dropped); ``None`` for every clip.
        out: a file for one named clip or a packed file, else a folder (made if missing) that
            gets one file per clip, named after it (:func:`clip_filenames`).
        format: a registered format (:func:`available_exporters`); ``None`` chooses it from the
            options and ``out``'s suffix (:func:`choose_exporter`).
        overwrite: replace existing files.
        skeletons: keep only clips on these database skeletons (ids; ``None``: any).
        command: what the output's lock records as its holder.
        progress: ``progress(iterable, total, desc)`` wrapping the files as written, or ``None``.
        select: selectors of the job's and the dataset's selection language (one string or a
            list, all of which a clip must pass; :mod:`torchsplice.store.select`), e.g.
            ``"role:spliced"`` or ``["method:naive", "label:action.style=elderly"]``; with
            ``clips``, the named clips it selects.
        index: with several clips in a folder of files, or in a packed file (even of one), also write ``index.csv``
            (each file's clip, split and every column ``torchsplice info --csv`` gives: role,
            labels, cost, flags, coverage ...) and, in a folder, ``train.txt``, ``val.txt`` and
            ``test.txt`` (:mod:`.index`); a format with a layout of its own (HumanML3D) writes its own.
        options: the format's options (``packed=True``, ``features="6d"`` for ``npz``), and
            every export's ``split_ratios`` (train, val, test fractions of the source clips;
            default 0.8, 0.1, 0.1) and ``split_seed`` (default 0), the index's splits.

    Everything is checked before any file is made (one-line
    :class:`~torchsplice.core.errors.TorchspliceError`: an unknown clip or format, an output of
    the wrong kind, an existing file without ``overwrite``); then every file is written under a
    hidden name and installed at the end (:mod:`.staging`): an error or an interrupt leaves no
    file of the export, no temporary and no folder it made. Returns an :class:`ExportResult`.
    """
    named = clips is not None
    if select is not None:
        clips = selected_names(database, select, clips)
    cls = choose_exporter(format, out, options)
    exporter = cls(database, clips, skeletons=skeletons, **{k: v for k, v in options.items() if k in cls.options})
    names = exporter.names
    layout = exporter.layout()
    if layout is not None:
        files, folder = folder_targets(out, layout, exporter, inputs=[database], overwrite=overwrite)
    else:
        single = exporter.single_file or (len(names) == 1 and named)
        suffix = Path(out).suffix.lower()
        if format is None and single and suffix and not Path(out).is_dir() and suffix not in {
                e.suffix.lower() for e in _REGISTRY.values()}:
            formats = ", ".join(f"{n} ({e.suffix})" if e.layout is Exporter.layout else f"{n} (a folder)"
                                for n, e in _REGISTRY.items())
            raise TorchspliceError(f"{out}: no export format writes {suffix} files; the formats are {formats} "
                                   "({format} chooses one)", options=("format",))
        files, folder = export_targets(out, names, exporter, single, inputs=[database], overwrite=overwrite)

    if options.get("split_ratios") is not None:
        parse_ratios(options["split_ratios"])  # bad ones refused before any work, index or not
    if options.get("split_seed") is not None:
        parse_seed(options["split_seed"])
    indexed = _index_targets(out, files, not single, database, overwrite) if index and layout is None and (
        exporter.single_file or not single) else {}
    if layout is not None and overwrite and Path(out).is_dir() and (why := exporter.foreign(Path(out))) is not None:
        raise TorchspliceError(f"{out}: {why}; {{overwrite}} replaces only what an earlier torchsplice export of the "
                               "folder wrote: export into a new folder", options=("overwrite",))
    exporter.check()
    # an earlier export's files, as its own record lists them, read before this export replaces that record
    earlier = exporter.owned(Path(out)) if layout is not None and overwrite and Path(out).is_dir() else []

    result = ExportResult(exporter.name, out, files, names)
    with staged_files(out, folder, overwrite=overwrite, command=command) as stage:
        items = exporter.items()
        try:
            count = 0
            for item in (items if progress is None else progress(items, len(files), f"export {exporter.name}")):
                if count == len(files):
                    raise TorchspliceError(f"format {exporter.name!r} ({type(exporter).__module__}) gave more files than the "
                                           f"{len(files)} of this export")
                _write(exporter, item, files[count], stage(files[count]), names)
                frames, fps = exporter.measure(item)
                result.frames += frames
                if fps is not None:
                    result.fps.append(fps)
                count += 1
        finally:
            if (close := getattr(items, "close", None)) is not None:
                close()
        if count != len(files):
            raise TorchspliceError(f"format {exporter.name!r} ({type(exporter).__module__}) gave {count} files of the "
                                   f"{len(files)} of this export")
        if indexed:
            texts = index_files(database, names, files, indexed, options.get("split_ratios"), options.get("split_seed"))
            counts = [texts[indexed[s]].count("\n") for s in ("train", "val", "test") if s in indexed]
            index_note = f"; {indexed['index'].name}" + (f", train/val/test {'/'.join(map(str, counts))}" if counts else "")
            result.index_files = list(texts)
            for target, text in texts.items():
                try:
                    stage(target).write_text(text)
                except OSError as exc:
                    raise TorchspliceError(os_error_message(target, exc)) from None
    if earlier:  # an earlier export's files this one did not write again
        written = set(files)
        for stale in earlier:
            if stale not in written:
                try:
                    stale.unlink()
                except FileNotFoundError:
                    pass
                except OSError as exc:
                    raise TorchspliceError(f"{os_error_message(stale, exc)} (an earlier export's file; the new export is "
                                           "in place)") from None
    result.summary_text = exporter.summary(result) + (index_note if indexed else "")
    result.summary_options = tuple(type(exporter).summary_options)
    result.summary = render_message(result.summary_text, result.summary_options)
    return result


def _index_targets(out, files: list[Path], folder_export: bool, database, overwrite: bool) -> dict[str, Path]:
    """The index's files (:func:`.index.index_targets`), checked like the clips' before any work."""
    targets = index_targets(out, folder_export)
    own = {t.as_posix().casefold() for t in targets.values()}  # case-blind, as the clips' names are checked
    clash = sorted(f for f in files if f.as_posix().casefold() in own)
    if clash:
        raise TorchspliceError(f"{clash[0]}: a clip's file would have the name of the export's index; export that clip "
                               "on its own, or without an index ({no_index})", options=("no_index",))
    for t in targets.values():
        if t.parent.is_dir():
            check_output(t, (t.suffix,), "an index" if t.suffix == ".csv" else "a split list", inputs=[database],
                         overwrite=overwrite)
    return targets


def _write(exporter: Exporter, item, target: Path, path: Path, names: list[str]) -> None:
    """``exporter.write(item, path)``: an OS error (a full disk) as one line naming ``target``;
    a plug-in's failure as one line naming the format (built-ins are trusted)."""
    try:
        exporter.write(item, path)
    except TorchspliceError:
        raise
    except OSError as exc:
        raise TorchspliceError(os_error_message(target, exc)) from None
    except (Exception, SystemExit) as exc:
        if type(exporter).__module__ in _BUILTIN_MODULES:  # a bug of ours: its traceback
            raise
        text = f"called sys.exit({exc.code!r})" if isinstance(exc, SystemExit) else \
            f"{type(exc).__name__}: {' '.join(str(exc).split())}"
        raise TorchspliceError(f"format {exporter.name!r} ({type(exporter).__module__}) failed writing {target}: "
                               f"{printable(text, limit=300)}; nothing written") from None


def export_targets(out, names: list[str], exporter: Exporter | type[Exporter], single_file: bool, inputs=(),
                   overwrite: bool = False) -> tuple[list[Path], Path | None]:
    """The files an export writes (one per clip, or one), checked before any work, and the folder
    to create (``None`` if none): ``out`` is a file for one clip or a packed file, else a folder."""
    out = Path(out)
    suffix, what = exporter.suffix, exporter.what
    if single_file and (not out.is_dir() or exporter.single_file):  # a packed file is never a folder
        return [check_output(out, (suffix,), what, inputs=inputs, overwrite=overwrite)], None
    if out.suffix.lower() in {e.suffix.lower() for e in _REGISTRY.values()} and not out.is_dir():
        packers = [e for e in _REGISTRY.values() if "packed" in e.options]
        raise TorchspliceError(f"{out}: {len(names)} clips go to a folder, one file each: give {{output}} a folder"
                               + (f" (or {{packed}} for one {packers[0].suffix})" if packers else ""),
                               options=("output", "packed") if packers else ("output",))
    if out.exists() and not out.is_dir():
        raise TorchspliceError(f"{out}: is a file; several clips go to a folder, one file each")
    if not out.parent.is_dir():
        raise TorchspliceError(f"{out}: folder {out.parent} does not exist")
    files = []
    for name in clip_filenames(names, suffix):  # safe everywhere, unique without regard to case
        f = out / name
        if out.is_dir():
            check_output(f, (suffix,), what, inputs=inputs, overwrite=overwrite)
        files.append(f)
    return files, None if out.is_dir() else out


def folder_targets(out, layout: list[str], exporter: Exporter, inputs=(),
                   overwrite: bool = False) -> tuple[list[Path], list[Path]]:
    """The files of a folder format's export (``layout``: paths inside ``out``), checked before
    any work, and the folders to create (``out`` and the subfolders, parents first)."""
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise TorchspliceError(f"{out}: is a file; the {exporter.title} format writes a folder: give {{output}} a folder",
                               options=("output",))
    if not out.is_dir() and out.suffix.lower() in {e.suffix.lower() for e in _REGISTRY.values()}:
        raise TorchspliceError(f"{out}: the {exporter.title} format writes a folder: give {{output}} a folder name "
                               f"(not a {out.suffix} file)", options=("output",))
    if not out.parent.is_dir():
        raise TorchspliceError(f"{out}: folder {out.parent} does not exist")
    files, folders = [], {out: None}
    for rel in layout:
        f = out.joinpath(*rel.split("/"))
        for parent in reversed(f.relative_to(out).parents[:-1]):
            folders.setdefault(out / parent, None)
        if f.parent.is_dir() or f.exists():
            check_output(f, (f.suffix,), f"a {f.suffix} file", inputs=inputs, overwrite=overwrite)
        files.append(f)
    if len({f.as_posix().casefold() for f in files}) != len(files):
        raise TorchspliceError(f"format {exporter.name!r} ({type(exporter).__module__}) names one file twice in its layout")
    return files, list(folders)


# --------------------------------------------------------------------------------------------
# choosing clips and naming their files
# --------------------------------------------------------------------------------------------
def select_rows(db: "MotionDatabase", clips: Sequence[str] | None, skeletons: Sequence[int] | None = None) -> list[int]:
    """Database rows of ``clips`` (names, in the order given, repeats dropped; ``None``: every clip
    in row order), kept only on ``skeletons`` (ids; ``None``: any). One-line errors for an
    unknown clip or skeleton and for an empty result."""
    rows = list(range(len(db))) if clips is None else list(dict.fromkeys(db.index(c) for c in clips))
    if skeletons is not None:
        unknown = [k for k in skeletons if k not in range(len(db.skeletons))]
        if unknown:
            raise TorchspliceError(f"{db.path}: no skeleton {unknown[0]} (it has {len(db.skeletons)}, numbered from 0; "
                                   "see {info})", options=("info",))
        skeleton = db.clip_table().skeleton
        rows = [r for r in rows if int(skeleton[r]) in set(skeletons)]
    if not rows:
        raise TorchspliceError(f"{db.path}: no clip to export" + (" on the skeletons asked for" if skeletons is not None else ""))
    return rows


_UNSAFE = re.compile(r'[\x00-\x1f\x7f<>:"/\\|?*]')
_RESERVED = re.compile(r"(con|prn|aux|nul|com[0-9¹²³]|lpt[0-9¹²³])(\..*)?", re.IGNORECASE)
MAX_FILE_BYTES = 200
"""Longest file name (UTF-8 bytes, suffix included) an export writes: file systems allow 255,
and the hidden name an export writes first adds a few dozen."""


def clip_filename(name: str, suffix: str) -> str:
    """A file name for clip ``name`` that is safe on Linux, macOS and Windows: characters that are
    not allowed there (``< > : " / \\ | ? *``, control characters) and a leading dot become
    ``_``, trailing dots and spaces go, Windows' device names (``CON``, ``nul.txt``, ``COM1``)
    get a ``_`` in front, and a name longer than :data:`MAX_FILE_BYTES` is cut and ends with a
    hash of the whole name. See :func:`clip_filenames` for names that are unique without regard
    to case."""
    safe = _UNSAFE.sub("_", name).rstrip(". ")
    if safe.startswith("."):
        safe = "_" + safe[1:]
    if _RESERVED.fullmatch(safe):
        safe = "_" + safe
    safe = safe or "_"
    room = MAX_FILE_BYTES - len(suffix.encode())
    if len(safe.encode()) > room:
        digest = hashlib.sha1(name.encode("utf-8", "surrogatepass")).hexdigest()[:12]
        safe = safe.encode()[:room - 13].decode(errors="ignore") + "~" + digest
    return safe + suffix


def clip_filenames(names, suffix: str) -> list[str]:
    """:func:`clip_filename` of each name, made unique without regard to case (``dup`` and ``DUP``
    are one file on macOS and Windows): a name whose file is taken gets ``~2``, ``~3``, ... in
    the order given, so the same clips always get the same files."""
    taken, out = set(), []
    for name in names:
        f = clip_filename(name, suffix)
        stem, k = f[:len(f) - len(suffix)], 1
        while f.casefold() in taken:
            k += 1
            f = clip_filename(f"{stem}~{k}", suffix)
        taken.add(f.casefold())
        out.append(f)
    return out


def selected_names(database, select: str | Sequence[str], clips: Sequence[str] | None = None) -> list[str]:
    """The names of the clips of ``database`` that ``select`` selects (in row order), or of
    ``clips`` (in their order) when given; a one-line error when none is."""
    from ..store.database import MotionDatabase  # h5py and torch: imported where used (module docstring)
    from ..store.select import select_clips

    with MotionDatabase.open(database) as db:
        table = db.clip_table()
        chosen = [table.names[r] for r in select_clips(table, select, "select", str(database))]
    if clips is None:
        return chosen
    keep = set(chosen)
    names = [c for c in clips if c in keep]
    if not names:
        raise TorchspliceError(f"{database}: none of the clips named is selected by {select!r}")
    return names
