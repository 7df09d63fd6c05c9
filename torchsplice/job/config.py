"""The job's configuration: one object that every part of the job reads.

:class:`JobConfig` holds what to splice (inputs, selections, methods, splice options, output
layout) and how to run it (engine, workers, device). Only the first half defines the job:
:meth:`JobConfig.plan_key` is what a resumed run must share with the run it resumes, so a
resume may use another engine or worker count. The splice options are derived here, once
(:meth:`JobConfig.align_options`, :meth:`JobConfig.splice_options`, :meth:`JobConfig.params`).
"""

from __future__ import annotations

import difflib
import json
import numbers
import os
from dataclasses import dataclass, fields, replace
from pathlib import Path

import numpy as np
import torch

from ..core.errors import TorchspliceError
from ..store.atomic import same_file
from ..store.defaults import COMPRESSIONS
from ..retarget.defaults import DEFAULT_FIX_FEET
from ..splice.defaults import (DEFAULT_ACTING_LIMBS, DEFAULT_BACKEND, DEFAULT_DEVICE, DEFAULT_FORCE, DEFAULT_MAX_RUN,
                               DEFAULT_POSTURE, DEFAULT_TIMING, DEFAULT_TWIST)
from ..splice.options import AlignOptions, SpliceOptions
from ..splice.backends import Backend, backend_for, get_backend, resolve_backend
from ..splice.registry import available_methods, get_method, plugin_modules
from ..splice.standing import LIMBS, TIMINGS, parse_limbs
from .defaults import (DEFAULT_ACTIONS, DEFAULT_ACTIONS_DB, DEFAULT_BATCH_PAIRS, DEFAULT_COMPRESSION, DEFAULT_COPY_SOURCES,
                       DEFAULT_ENGINE, DEFAULT_INDEX, DEFAULT_KEEP_HANDS_OUT, DEFAULT_LAYOUT, DEFAULT_LOCOMOTIONS,
                       DEFAULT_MAX_LENGTH_RATIO, DEFAULT_MEMORY_BUDGET_MB, DEFAULT_METHODS, DEFAULT_RAY_ADDRESS,
                       DEFAULT_RETARGET, DEFAULT_STORE, DEFAULT_TARGET, DEFAULT_WORKERS, LAYOUTS, STORES, usable_cores)
from .engines.registry import available_engines

__all__ = ["JobConfig", "job_config", "DEFAULT_LOCOMOTIONS", "DEFAULT_ACTIONS", "LAYOUTS", "STORES", "parse_shard"]

# DEFAULT_LOCOMOTIONS, DEFAULT_ACTIONS, LAYOUTS, STORES and the fields' defaults are declared in .defaults
# (torch-free: the command line reads them there)


@dataclass(frozen=True)
class JobConfig:
    """Everything that defines a job and how it runs.

    What to splice (the plan):
        database: the motion database holding the locomotions (and the actions, by default).
        output: the database to write.
        actions_db: another database holding the actions (any humanoid skeleton: see ``retarget``).
        locomotions, actions: selectors, all of which must select a clip.
        methods: one or several registered methods: ``splice``, ``naive``, ``cpmc`` or plug-ins
            (see :mod:`torchsplice.splice.registry`).
        force_locomotion: splice clips that do not locomote instead of skipping their pairs.
        max_length_ratio: skip pairs whose longer clip lasts more than this many times the
            shorter one (``None``: no limit).
        timing: how a standing action (one that does not locomote) fills its locomotion:
            ``"loop"`` (default), ``"hold"`` or ``"fit"`` (onto a shorter locomotion, loop and
            hold play the action's window where the acting arms move most; see
            :mod:`torchsplice.splice.standing`); unless ``force_locomotion`` makes the timewarp
            align it anyway.
        acting_limbs: the arms standing actions act with (``None``: found per clip).
        retarget: form the pairs whose clips are on different skeletons (other joints, or other
            units) by retargeting the action onto the locomotion's skeleton, once per action
            and target skeleton (:mod:`torchsplice.ops.retarget`); ``False`` skips them.
        fix_feet: when retargeting, hold the feet where the source's stand (:mod:`torchsplice.ops.feet`).
        target: bring every clip onto this skeleton first (``"other.h5"``, ``"other.h5:K"``, a BVH
            file or ``"smpl22"``; :func:`torchsplice.retarget.resolve_target`), into databases
            beside the output (:mod:`torchsplice.job.target`); ``None``: each pair on its
            locomotion's skeleton.
        copy_sources: copy the selected source clips into the output too.
        index: write ``NAME.h5.index.csv`` beside the output when it is complete: every clip's row
            of ``torchsplice info --csv`` (cost, alignment_distance, flags, coverage, role,
            locomotion, action, labels ...) and its split by source clip
            (:func:`torchsplice.formats.index.write_database_index`; ``NAME.h5.index.csv.gz``,
            gzip-compressed, from a spreadsheet's 1,048,576 rows on). Not part of the plan: a
            resumed run may change it.
        max_run, posture, twist: splicing parameters (see :class:`~torchsplice.splice.SpliceOptions`).
        keep_hands_out: where a result puts a hand or forearm inside its body deeper than its
            sources do, move the arm out by two-bone IK on the shoulder and elbow, smoothly in
            time (:mod:`torchsplice.ops.hands`); the ``corrected_frames`` column counts the
            frames changed. ``False`` writes the splice as it comes.
        compression: the output's compression (see :meth:`MotionDatabase.create`): ``"auto"``
            (LZF on everything but rotations: fast, read by h5py), ``"lzf"``, ``"gzip"`` (read by
            every HDF5 tool, several times slower to write) or ``None``.
        layout: ``"copy"`` (one self-contained file) or ``"virtual"`` (the output's frames are
            HDF5 virtual datasets over the shards, kept in ``OUT.shards/`` beside it: no copy).
        store: ``"motion"`` (each spliced clip's frames) or ``"alignment"`` (each source clip
            once and, per spliced clip, what splicing computed: its alignment curve, the
            pelvis's rotation per frame, a standing action's timing; every read assembles the
            motion, bit for bit the motion store's; about a tenth of the disk and less; see
            :mod:`torchsplice.store.assembly`). Methods whose result is not an alignment
            (``cpmc`` through the timewarp, plug-ins) keep their frames in either.
        memory_budget_mb: bound on the memory of one task, which sets the pairs per task.
        batch_pairs: pairs per task; ``None`` derives it from the budget.

    How to run it (free to change between a run and its resume):
        engine: ``"local"`` (worker processes on this machine), ``"ray"`` (Ray tasks) or a
            registered engine (see :mod:`torchsplice.job.engines`).
        workers: local worker processes (``None``: one per core); each computes with one thread.
        ray_address: the Ray cluster to use (``None``: start a local Ray instance).
        device: ``None``/``"cpu"`` for the compiled CPU splicer, or a torch device such as
            ``"cuda"`` (then the torch splicer runs in this process).
        backend: the splicing backend: ``"auto"`` (the compiled splicer on the CPU, torch on
            CUDA), ``"compiled"``, ``"torch"`` or a registered one (see
            :mod:`torchsplice.splice.backends`). A resumed run must resolve to the same one.
    """

    database: Path
    output: Path
    actions_db: Path | None = DEFAULT_ACTIONS_DB
    locomotions: tuple[str, ...] = DEFAULT_LOCOMOTIONS
    actions: tuple[str, ...] = DEFAULT_ACTIONS
    methods: tuple[str, ...] = DEFAULT_METHODS
    force_locomotion: bool = DEFAULT_FORCE
    max_length_ratio: float | None = DEFAULT_MAX_LENGTH_RATIO
    timing: str = DEFAULT_TIMING
    acting_limbs: tuple[str, ...] | None = DEFAULT_ACTING_LIMBS
    retarget: bool = DEFAULT_RETARGET
    fix_feet: bool = DEFAULT_FIX_FEET
    target: str | None = DEFAULT_TARGET
    copy_sources: bool = DEFAULT_COPY_SOURCES
    index: bool = DEFAULT_INDEX
    max_run: int = DEFAULT_MAX_RUN
    posture: bool = DEFAULT_POSTURE
    twist: float = DEFAULT_TWIST
    keep_hands_out: bool = DEFAULT_KEEP_HANDS_OUT
    compression: str | None = DEFAULT_COMPRESSION
    layout: str = DEFAULT_LAYOUT
    store: str = DEFAULT_STORE
    memory_budget_mb: int = DEFAULT_MEMORY_BUDGET_MB
    batch_pairs: int | None = DEFAULT_BATCH_PAIRS
    engine: str = DEFAULT_ENGINE
    workers: int | None = DEFAULT_WORKERS
    ray_address: str | None = DEFAULT_RAY_ADDRESS
    device: str | None = DEFAULT_DEVICE
    backend: str = DEFAULT_BACKEND

    def checked(self) -> "JobConfig":
        """The configuration with paths and names normalised; a clear error for a bad value."""
        _check_types(self)
        c = self
        if c.compression == "none":
            c = replace(c, compression=None)
        if c.compression not in COMPRESSIONS:
            raise TorchspliceError(f"unknown compression {c.compression!r}; choose auto, lzf, gzip or none")
        if not c.methods:
            raise TorchspliceError(f"no method given; choose from {', '.join(available_methods())}")
        for m in c.methods:
            get_method(m)  # a clear error naming the available methods
        if c.engine not in available_engines():
            raise TorchspliceError(f"unknown engine {c.engine!r}; choose one of {', '.join(available_engines())}")
        if c.layout not in LAYOUTS:
            raise TorchspliceError(f"unknown layout {c.layout!r}; choose {' or '.join(LAYOUTS)}")
        if c.store not in STORES:
            near = difflib.get_close_matches(str(c.store), STORES, n=1)
            raise TorchspliceError(f"unknown store {c.store!r}" + (f"; did you mean {near[0]!r}?" if near else "")
                                   + f" (choose {' or '.join(STORES)})")
        if c.layout == "virtual" and c.copy_sources:
            raise TorchspliceError("{copy_sources} needs {layout} copy: a virtual output holds only the spliced clips",
                                   options=("copy_sources", "layout"))

        if c.timing not in TIMINGS:
            raise TorchspliceError(f"unknown timing {c.timing!r}; choose {', '.join(TIMINGS)}")
        if c.acting_limbs is not None and any(x not in LIMBS for x in c.acting_limbs):
            raise TorchspliceError(f"unknown acting limb in {','.join(c.acting_limbs)!r}; choose from {', '.join(LIMBS)}")
        if not 0.0 <= c.twist <= 1.0:
            raise TorchspliceError(f"{{twist}} must be a share from 0 to 1, got {c.twist}", options=("twist",))
        if c.max_length_ratio is not None and not c.max_length_ratio >= 1:
            raise TorchspliceError(f"{{max_length_ratio}} must be at least 1, got {c.max_length_ratio}",
                                   options=("max_length_ratio",))

        resolve_backend(c.backend, c.device)  # a clear error for an unknown one, or one that cannot run there
        target_file = None
        if c.target is not None:
            from ..retarget.targets import resolve_target  # loaded by jobs that retarget, not by every worker

            target_file = resolve_target(str(c.target)).path  # a clear error now for a target that is not one
            c = replace(c, target=str(c.target))
        if c.workers is not None and c.workers < 1:
            raise TorchspliceError(f"{{workers}} must be at least 1, got {c.workers}", options=("workers",))
        dup = sorted({m for m in c.methods if c.methods.count(m) > 1})
        if dup:
            raise TorchspliceError(f"method {dup[0]!r} is asked for twice; name each method once")
        c = replace(c, database=Path(c.database), output=Path(c.output),
                    actions_db=Path(c.actions_db) if c.actions_db is not None else None)
        if c.actions_db is not None and c.actions_db.resolve() == c.database.resolve():
            c = replace(c, actions_db=None)
        out = c.output
        if out.suffix.lower() not in (".h5", ".hdf5"):
            raise TorchspliceError(f"{out}: the output is a database, so its name must end in .h5 or .hdf5")
        if out.is_dir():
            raise TorchspliceError(f"{out}: is a folder; give the output a file name ending in .h5")
        if not out.parent.is_dir():
            raise TorchspliceError(f"{out}: folder {out.parent} does not exist")
        for source, what in ((c.database, "database"), (c.actions_db, "{actions_db}"), (target_file, "{target}")):
            if source is not None and same_file(out, source):  # --force never replaces an input
                raise TorchspliceError(f"{out}: is also the job's input ({what}); write the output to another file",
                                       options=("actions_db", "target"))
        if c.store == "alignment":
            _check_stores_alignments(c)
        return c

    @property
    def work(self) -> Path:
        """The job's work folder beside the output: its plan, shards and locks."""
        return self.output.with_name(f".{self.output.name}.parts")

    @property
    def shards_folder(self) -> Path:
        """Where a ``virtual`` output keeps its shards (they are part of the output)."""
        return self.output.with_name(f"{self.output.name}.shards")

    def worker_count(self) -> int:
        """Local worker processes: ``workers``, or one per core."""
        if self.workers:
            return self.workers
        return usable_cores()

    def uses_worker_processes(self) -> bool:
        """Whether the ``local`` engine runs worker processes: more than one worker, and a backend
        whose prepared clips they share (:attr:`~torchsplice.splice.backends.Backend.prepares_once`);
        otherwise the job splices in this process. (:func:`.engines.forkserver.prestart` asks the
        same before a config exists.)"""
        return self.worker_count() > 1 and self.splice_backend().prepares_once

    def align_options(self) -> AlignOptions:
        return AlignOptions(max_run=self.max_run)

    def splice_options(self) -> SpliceOptions:
        """Options for :func:`~torchsplice.splice.splice_pairs` (the plan has checked every clip)."""
        return SpliceOptions(align=self.align_options(), posture=self.posture, force=True, check_locomotion=False,
                             device=self.device, timing=self.timing, acting_limbs=self.acting_limbs, twist=self.twist,
                             backend=self.backend)

    def params(self) -> str:
        """The ``params`` column of every spliced clip (JSON)."""
        return json.dumps({"max_run": self.max_run, "posture": self.posture, "twist": self.twist,
                           "heading_window_deg": self.align_options().heading_window_deg,
                           "force_locomotion": self.force_locomotion, "timing": self.timing,
                           "acting_limbs": None if self.acting_limbs is None else list(self.acting_limbs)})

    def resolved_backend(self) -> str:
        """The backend's name :attr:`backend` means on :attr:`device`: ``"compiled"`` (the CPU
        splicer), ``"torch"`` (CUDA, or no numba) or a registered one."""
        return resolve_backend(self.backend, self.device)

    def splice_backend(self, method: str | None = None):
        """The :class:`~torchsplice.splice.backends.Backend` that splices ``method`` in this job
        (``None``: the job's own, :meth:`resolved_backend`)."""
        name = self.resolved_backend()
        return get_backend(name) if method is None else backend_for(get_method(method), name)

    def plan_key(self) -> dict:
        """The settings a resumed run must share with the run it resumes (the backend too: the
        compiled splicer computes in float64, torch in float32)."""
        return {"backend": self.resolved_backend(),
            "locomotions": list(self.locomotions), "actions": list(self.actions), "methods": list(self.methods),
            "force_locomotion": self.force_locomotion, "max_run": self.max_run, "posture": self.posture,
            "keep_hands_out": self.keep_hands_out,
            "copy_sources": self.copy_sources, "compression": self.compression, "layout": self.layout,
            **({"store": self.store} if self.store != "motion" else {}),  # plans of motion stores stay valid
            **({"max_length_ratio": self.max_length_ratio} if self.max_length_ratio is not None else {}),
            **({"twist": self.twist} if self.twist else {}),  # plans of runs without it stay valid
            "timing": self.timing, "acting_limbs": None if self.acting_limbs is None else list(self.acting_limbs),
            "retarget": self.retarget, "fix_feet": self.fix_feet, "target": self.target,
            **({"plugins": plugin_modules(self.methods)} if plugin_modules(self.methods) else {}),
        }


def _check_stores_alignments(c: JobConfig) -> None:
    """Refuse ``store="alignment"`` with a backend that gives no parts to store (the torch
    splicer, or a plug-in that does not implement :meth:`~torchsplice.splice.backends.Backend.assembly_bank`),
    here, before the job plans or creates its work folder (and in a dry run as in a run)."""
    backend = c.splice_backend()
    if type(backend).assembly_bank is Backend.assembly_bank:
        raise TorchspliceError(f"{c.output}: the {backend.name} splicer gives no alignments to store; write {{store}} motion",
                               options=("store",))


def _is_int(v) -> bool:
    return isinstance(v, numbers.Integral) and not isinstance(v, bool)


def _check_types(c: JobConfig) -> None:
    """One-line errors, naming the option, for values of the wrong type or range (the Python
    API takes anything; the command line's parsers already checked theirs)."""
    def bad(name: str, want: str, value) -> TorchspliceError:
        return TorchspliceError(f"{{{name}}} must be {want}, got {value!r}", options=(name,))

    for name in ("database", "output", "actions_db"):
        v = getattr(c, name)
        if not (isinstance(v, (str, os.PathLike)) or (v is None and name == "actions_db")):
            raise bad(name, "a path", v)
    for name in ("locomotions", "actions", "methods"):
        v = getattr(c, name)
        if not isinstance(v, tuple) or not all(isinstance(x, str) for x in v):
            raise bad(name, "a string or a sequence of strings", v)
    for name in ("force_locomotion", "copy_sources", "index", "posture", "retarget", "fix_feet", "keep_hands_out"):
        if not isinstance(getattr(c, name), (bool, np.bool_)):
            raise bad(name, "True or False", getattr(c, name))
    for name, lo, optional in (("max_run", 1, False), ("memory_budget_mb", 1, False), ("batch_pairs", 1, True),
                               ("workers", 1, True)):
        v = getattr(c, name)
        if v is None and optional:
            continue
        if not _is_int(v):
            raise bad(name, "a whole number" + (" or None" if optional else ""), v)
        if v < lo:
            raise bad(name, f"at least {lo}", v)
    v = c.max_length_ratio
    if v is not None and (not isinstance(v, numbers.Real) or isinstance(v, bool)):
        raise bad("max_length_ratio", "a number or None", v)
    if c.acting_limbs is not None and (not isinstance(c.acting_limbs, tuple)
                                       or not all(isinstance(x, str) for x in c.acting_limbs)):
        raise bad("acting_limbs", "None, 'auto', 'none', 'both' or arm names", c.acting_limbs)
    for name in ("ray_address", "device", "compression", "backend", "store"):
        v = getattr(c, name)
        if v is not None and not isinstance(v, str):
            raise bad(name, "a string or None", v)


def check_device(name: str | None) -> str | None:
    """A torch device name checked up front (``None``: the CPU): one clear line for an unknown,
    unsupported or absent device instead of a traceback later."""
    if name is None:
        return None
    if not isinstance(name, str):
        raise TorchspliceError(f"{{device}} must be a string such as 'cpu' or 'cuda', got {name!r}", options=("device",))

    try:
        dev = torch.device(name)
    except (RuntimeError, ValueError):
        raise TorchspliceError(f"unknown device {name!r} (use cpu, cuda or cuda:N)") from None
    if dev.type == "cuda" and not torch.cuda.is_available():
        raise TorchspliceError(f"device {name!r} asked for, but this torch sees no CUDA device")
    if dev.type == "cuda" and dev.index is not None and dev.index >= torch.cuda.device_count():
        raise TorchspliceError(f"device {name!r} asked for, but this torch sees {torch.cuda.device_count()} CUDA devices")
    if dev.type not in ("cpu", "cuda"):
        raise TorchspliceError(f"device {name!r} is not supported (use cpu or cuda)")
    return name


def job_config(database, output, **options) -> JobConfig:
    """A checked :class:`JobConfig` from the same values the command line takes, as the Python
    API (:func:`torchsplice.job.splice_all`) and ``torchsplice splice-all`` both build it.

    ``options`` are :class:`JobConfig` fields. For convenience, ``locomotions`` and ``actions``
    may be one selector string (``"role:locomotion,role:both"``) or a sequence of them (every one
    must match), ``None`` for the default; ``methods`` a comma-separated string
    (``"splice,naive"``) or a sequence; ``acting_limbs`` ``"auto"``, ``"none"``, ``"both"`` or
    ``"left_arm,right_arm"`` as well as a tuple. An unknown option is an error naming the
    options there are.
    """
    known = [f.name for f in fields(JobConfig) if f.name not in ("database", "output")]
    bad = sorted(set(options) - set(known))
    if bad:
        raise TorchspliceError(f"unknown job option {bad[0]!r}; the options are {', '.join(known)}")
    def strings(key: str, value) -> tuple:
        if isinstance(value, str):
            return (value,)
        if not isinstance(value, (list, tuple)) or not all(isinstance(x, str) for x in value):
            raise TorchspliceError(f"{{{key}}} must be a string or a sequence of strings, got {value!r}", options=(key,))
        return tuple(value)

    for key, default in (("locomotions", DEFAULT_LOCOMOTIONS), ("actions", DEFAULT_ACTIONS)):
        value = options.get(key, default)
        options[key] = default if value is None or value == () or value == [] else strings(key, value)
    methods = options.get("methods", DEFAULT_METHODS)
    methods = methods.split(",") if isinstance(methods, str) else strings("methods", methods)
    options["methods"] = tuple(m.strip() for m in methods if m.strip())
    options["device"] = check_device(options.get("device"))
    limbs = options.get("acting_limbs")
    if isinstance(limbs, str):
        try:
            options["acting_limbs"] = parse_limbs(limbs)
        except ValueError as exc:
            raise TorchspliceError(f"{{acting_limbs}}: {exc}", options=("acting_limbs",)) from None
    elif limbs is not None:
        if not isinstance(limbs, (list, tuple)):
            raise TorchspliceError(f"{{acting_limbs}} must be None, 'auto', 'none', 'both' or arm names, got {limbs!r}",
                                   options=("acting_limbs",))
        options["acting_limbs"] = tuple(limbs)
    for name, v in (("database", database), ("output", output)):
        if not isinstance(v, (str, os.PathLike)):
            raise TorchspliceError(f"{name} must be a path, got {v!r}")
    return JobConfig(database=Path(database), output=Path(output), **options).checked()


def parse_shard(text) -> tuple[int, int]:
    """``"K/N"`` (or ``(K, N)``) as ``(K, N)`` with ``1 <= K <= N``; a clear error otherwise."""
    if isinstance(text, (tuple, list)):
        if len(text) != 2 or not all(_is_int(x) for x in text):
            raise TorchspliceError(f"{{shard}} must be 'K/N' or (K, N), got {text!r}", options=("shard",))
        text = f"{text[0]}/{text[1]}"
    if not isinstance(text, str):
        raise TorchspliceError(f"{{shard}} must be 'K/N' or (K, N), got {text!r}", options=("shard",))
    try:
        k, n = (int(x) for x in text.split("/"))
    except ValueError:
        raise TorchspliceError(f"{{shard}} must look like K/N (e.g. 2/8), got {_cut(text)!r}", options=("shard",)) from None
    if not 1 <= k <= n:
        raise TorchspliceError(f"{{shard}} {_cut(text)}: K must be between 1 and N", options=("shard",))
    if n > MAX_SLICES:
        raise TorchspliceError(f"{{shard}} {_cut(text)}: at most {MAX_SLICES:,} slices (N); a slice is at least one task",
                               options=("shard",))
    return k, n


MAX_SLICES = 100_000
"""The most slices (``--shard K/N``'s N) a job is cut into."""


def _cut(text: str, n: int = 40) -> str:
    return text if len(text) <= n else text[:n] + "..."
