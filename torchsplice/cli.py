"""The ``torchsplice`` command line.

Every user mistake (a malformed file, an unknown clip, a spec that does not fit) prints one
line ``torchsplice: error: ...`` and exits non-zero; tracebacks are for bugs only.
Exit codes: 0 success, 1 finished with problems (e.g. some files skipped), 2 error or bad
usage, 130 interrupted.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import shlex
import sys
import warnings
from pathlib import Path

from .core.version import __version__
from .core.errors import OutputExistsError, TorchspliceError

__all__ = ["main", "build_parser"]


_CLI_HINTS = {  # what the library's error hints (torchsplice.core.errors.HINTS) are on the command line
    "overwrite": "use --force to overwrite",
    "force_locomotion": "--force-locomotion splices it anyway",
    "restart": "pass --restart to discard it",
}
_FLAGS = {"overwrite": "--force"}  # library option -> flag, where it is not --the-same-name


def _flag(option: str) -> str:
    """A library option's command-line flag (``max_length_ratio`` -> ``--max-length-ratio``)."""
    return _FLAGS.get(option, "--" + option.replace("_", "-"))


def cli_message(exc: BaseException) -> str:
    """An error's message as the command line says it: the options it names as flags
    (``{max_length_ratio}`` -> ``--max-length-ratio``) and its hint in flag terms."""
    from .core.errors import HINTS, render_message

    if not isinstance(exc, TorchspliceError) or not hasattr(exc, "message"):
        return str(exc)
    text = render_message(exc.message, exc.options, _flag)
    hint = _CLI_HINTS.get(exc.hint) or HINTS.get(exc.hint) if exc.hint else None
    return f"{text} ({hint})" if hint else text


def _progress(iterable, total: int, desc: str, quiet: bool):
    """A tqdm progress bar on stderr (hidden with --quiet or when stderr is not a terminal)."""
    from tqdm import tqdm

    return tqdm(iterable, total=total, desc=desc, unit="file", disable=True if quiet else None,
                file=sys.stderr, dynamic_ncols=True)


_OUTPUTS = {  # kind of output: (suffixes, what it is)
    "database": ((".h5", ".hdf5"), "a database"),
    "bvh": ((".bvh",), "BVH"),
    "npz": ((".npz",), "a NumPy .npz file"),
    "report": ((".md",), "a Markdown report"),
    "plot": ((".png", ".pdf", ".svg"), "a picture"),
    "render": ((".gif", ".mp4", ".png"), "a GIF, MP4 or PNG filmstrip"),
    "viewer": ((".html", ".htm"), "an HTML page"),
}


def _output(args, kind: str, inputs=()) -> Path:
    """``args.output`` checked before any work: the right suffix for ``kind``, not a folder,
    not one of ``inputs``, and not an existing file unless ``--force``."""
    from .store.atomic import check_output

    suffixes, what = _OUTPUTS[kind]
    return check_output(args.output, suffixes, what, inputs=inputs, overwrite=getattr(args, "force", False))


@contextlib.contextmanager
def _locked(out: Path, args):
    """Hold the output's lock while the command writes it: a second writer is refused at once."""
    from .store.lock import output_lock

    with output_lock(out, "torchsplice " + shlex.join(getattr(args, "argv", []))):
        if out.exists() and not getattr(args, "force", False):  # written meanwhile by another process
            raise OutputExistsError(f"{out}: already exists")
        yield out


def _read_pair(db, args):
    """The ``--locomotion`` and ``--action`` clips of an open database, and the spec that fits them."""
    loco, act = db.read(args.locomotion), db.read(args.action)
    return loco, act, _db_spec(db, db.clip_info(args.locomotion)["skeleton"], loco.skeleton)


def _say(args, msg: str) -> None:
    if not getattr(args, "quiet", False):
        print(msg)


def _n(count: int, word: str) -> str:
    """``"1 clip"``, ``"2 clips"``: a count with its noun, plural unless one."""
    return f"{count} {word}{'' if count == 1 else 's'}"


# --------------------------------------------------------------------------------------------
# sample
# --------------------------------------------------------------------------------------------
def cmd_sample(args) -> int:
    from .store.database import MotionDatabase
    from .sample import sample_motions
    from .specs import load_spec

    out = _output(args, "database")
    spec = load_spec("sample")
    motions = sample_motions()
    db = MotionDatabase.create(out, overwrite=args.force)
    with db:
        for m in motions:
            db.append(m, spec=spec)
    frames = sum(m.num_frames for m in motions)
    roles = {}
    for m in motions:
        roles[m.role] = roles.get(m.role, 0) + 1
    _say(args, f"wrote {args.output}: {len(motions)} synthetic clips ({frames} frames at 30 fps), "
               + ", ".join(f"{n} {r}" for r, n in sorted(roles.items())))
    return 0


# --------------------------------------------------------------------------------------------
# import
# --------------------------------------------------------------------------------------------
def cmd_import(args) -> int:
    from .formats.importer import NothingImportedError, import_bvh

    def skipped_lines(skipped):
        for f, why in skipped:
            print(f"skipped {_at(f, why)}", file=sys.stderr)

    try:
        report = import_bvh(args.paths, args.output, spec=args.spec, append=args.append, overwrite=args.force,
                            float64=args.float64, split=args.split, split_overlap=args.split_overlap, units=args.units,
                            progress=lambda it, total, desc: _progress(it, total, desc, args.quiet))
    except NothingImportedError as exc:
        skipped_lines(exc.report.skipped)
        raise
    for g in report.guessed:
        _say(args, f"skeleton {g.skeleton} (first seen in {g.path}): joint roles guessed by the {g.spec!r} spec "
                   "(check them; a dataset spec fixes them):\n" + "\n".join(f"  {ln}" for ln in g.summary))
    cut = report.cut
    # a cut take is one file but several clips: count the clips written, and the files when they differ
    added = sum(c.windows for c in report.imported)
    files = f" from {_n(len(report.imported), 'file')}" if added != len(report.imported) else ""
    _say(args, f"imported {_n(added, 'clip')}{files} ({report.frames} frames) into {args.output} "
               f"({_n(report.clips, 'clip')} in all)"
               + (f"; {_n(len(cut), 'long take')} cut into {sum(c.windows for c in cut)} windows of {args.split:g} s"
                  if cut else ""))
    for f, why in report.warnings:
        print(f"warning: {_at(f, why)}", file=sys.stderr)
    skipped_lines(report.skipped)
    if report.skipped:
        print(f"{len(report.skipped)} input(s) skipped, {len(report.imported)} imported", file=sys.stderr)
    return 1 if report.skipped else 0


def _at(path, why: str) -> str:
    """``PATH: why``, or ``PATH:LINE: rest`` when ``why`` starts with a line number."""
    from .core.names import printable

    head, sep, _ = why.partition(":")
    path = printable(path)  # a file's name may hold control characters
    return f"{path}:{why}" if sep and head.isdigit() else f"{path}: {why}"


def _one_line(message, path=None, limit: int = 300) -> str:
    """``message`` as one line of at most ``limit`` characters, without a leading ``PATH:``."""
    from .formats.importer import one_line

    return one_line(message, path, limit)


# --------------------------------------------------------------------------------------------
# info and export
# --------------------------------------------------------------------------------------------
def _labels_text(labels: dict) -> str:
    return " ".join(f"{k}={v}" for k, v in sorted(labels.items()))


def cmd_info(args) -> int:
    from .store.database import MotionDatabase

    with MotionDatabase.open(args.database) as db:
        s = db.summary()
    if args.json:
        print(json.dumps(s, indent=2))
        return 0
    minutes = s["duration_s"] / 60
    print(f"{s['path']}: {_n(s['num_clips'], 'clip')}, {s['num_frames']} frames ({minutes:.1f} min); "
          f"schema {s['schema_version']}, units {s['units'] or '?'}, up axis {s['up_axis'] or '?'}, "
          f"quaternions {s['quaternion_order']}")
    for k in s["skeletons"]:
        print(f"skeleton {k['id']}: {k['joints']} joints, root {k['root']}, spec {k['spec'] or '-'}"
              f"{' (roles guessed)' if k['guessed_roles'] else ''}, units {k['units'] or '?'}, "
              f"up axis {k['up_axis'] or '?'}, {_n(k['clips'], 'clip')}")
    print("roles: " + ", ".join(f"{r} {n}" for r, n in sorted(s["roles"].items())))
    run = s.get("run")
    if isinstance(run, dict):
        print(f"run: {run.get('command', '?')} ({run.get('tool', 'torchsplice')}, started {run.get('started', '?')})")
    if s["clips"]:
        w = max(4, max(len(c["name"]) for c in s["clips"]))
        print(f"{'name':<{w}}  {'frames':>6}  {'fps':>5}  {'sec':>6}  {'role':<10}  labels")
        for c in s["clips"]:
            print(f"{c['name']:<{w}}  {c['frames']:>6}  {c['fps']:>5g}  {c['duration_s']:>6.2f}  "
                  f"{c['role'] or '-':<10}  {_labels_text(c['labels'])}")
    return 0


def _export_targets(args, names: list[str], suffix: str, single_file: bool) -> tuple[list[Path], Path | None]:
    """The files ``export`` writes (one per clip, or one), checked before any work, and the folder
    to create (``None`` if none): ``-o`` is a file for one clip or a packed file, else a folder."""
    from .store.atomic import check_output
    from .formats.npz import clip_filenames

    kind = "npz" if suffix == ".npz" else "bvh"
    out = Path(args.output)
    if single_file and (not out.is_dir() or getattr(args, "packed", False)):  # a packed file is never a folder
        return [_output(args, kind, inputs=[args.database])], None
    if out.suffix.lower() in (".bvh", ".npz") and not out.is_dir():
        raise TorchspliceError(f"{out}: {len(names)} clips go to a folder, one file each: give -o a folder "
                               "(or --packed for one .npz)")
    if out.exists() and not out.is_dir():
        raise TorchspliceError(f"{out}: is a file; several clips go to a folder, one file each")
    if not out.parent.is_dir():
        raise TorchspliceError(f"{out}: folder {out.parent} does not exist")
    files = []
    for name in clip_filenames(names, suffix):  # safe everywhere, unique without regard to case
        f = out / name
        if out.is_dir():
            check_output(f, (suffix,), _OUTPUTS[kind][1], inputs=[args.database], overwrite=args.force)
        files.append(f)
    return files, None if out.is_dir() else out


def _make_folder(folder: Path) -> None:
    """Create the output folder of an export; an OS error (permission, full disk) is one line."""
    from .store.atomic import os_error_message

    try:
        folder.mkdir(exist_ok=True)
    except OSError as exc:
        raise TorchspliceError(os_error_message(folder, exc)) from None
    if not folder.is_dir():
        raise TorchspliceError(f"{folder}: is a file; several clips go to a folder, one file each")


@contextlib.contextmanager
def _all_or_nothing(args, folder: Path | None):
    """Write an export's files all or none: yields ``stage(file) -> path`` to write each one to
    (a hidden name beside it, ``.NAME.staged-HOST-PID``; those a killed export left are removed
    first); at the end every staged file is renamed
    to its name. On an error or an interrupt the staged files go, with the ``folder`` made for
    them (``None``: none to make), and no file of the export appears, so the same command runs
    again as it was. The output (``-o``: a file or the folder) is locked meanwhile: a second
    export to it is refused at once."""
    import os

    from .store.atomic import os_error_message
    from .store.lock import output_lock, remove_stale_temporaries, temp_path

    staged: dict[Path, Path] = {}

    def stage(f: Path) -> Path:
        if f.parent not in {g.parent for g in staged}:  # what a killed export left there goes first
            remove_stale_temporaries(f.parent, "staged")
        staged[f] = temp_path(f, "staged")
        return staged[f]

    with output_lock(Path(args.output), "torchsplice " + shlex.join(getattr(args, "argv", []))):
        if folder is not None:
            _make_folder(folder)
        try:
            yield stage
            taken = [f for f in staged if f.exists()] if not args.force else []
            if taken:  # written meanwhile by another process
                raise OutputExistsError(f"{taken[0]}: already exists")
            for f, tmp in staged.items():
                try:
                    os.replace(tmp, f)
                except OSError as exc:
                    raise TorchspliceError(os_error_message(f, exc)) from None
        except BaseException:
            for tmp in staged.values():
                with contextlib.suppress(OSError):
                    tmp.unlink()
            if folder is not None:
                with contextlib.suppress(OSError):
                    folder.rmdir()  # made for this export, and empty again
            raise


def cmd_export(args) -> int:
    import torch

    from .formats.bvh import write_bvh
    from .store.database import MotionDatabase
    from .formats.npz import select_rows

    if args.all == bool(args.clips):
        raise TorchspliceError("name the clips to export, or pass --all (not both)" if args.all else
                               "name the clips to export (as `torchsplice info` lists them), or pass --all")
    fmt = args.format or ("npz" if Path(args.output).suffix.lower() == ".npz" or args.packed or args.features else "bvh")
    if fmt == "bvh" and (args.packed or args.features):
        raise TorchspliceError(f"{'--packed' if args.packed else '--features'} needs --format npz (BVH holds one clip per file)")
    skeletons = None
    if args.skeleton is not None:
        try:
            skeletons = sorted({int(k) for k in args.skeleton.split(",") if k.strip()})
        except ValueError:
            raise TorchspliceError(f"--skeleton: expected skeleton ids such as 0 or 0,1, got {args.skeleton!r}") from None
    if fmt == "npz":
        from .formats.npz import NpzExport, write_npz

        export = NpzExport(args.database, None if args.all else args.clips, features=args.features, skeletons=skeletons)
        names = export.names
        files, folder = _export_targets(args, names, ".npz", single_file=args.packed or (len(names) == 1 and not args.all))
        if args.packed:
            arrays = export.packed()
            with _locked(files[0], args):
                write_npz(files[0], arrays)
            _say(args, f"wrote {files[0]}: {len(names)} clips packed, {export.num_frames} frames"
                       + (f", features {args.features} with statistics" if args.features else ""))
            return 0
        export.statistics  # computed (and checked) before anything is made
        with _all_or_nothing(args, folder) as stage:
            for (name, arrays), f in zip(export.per_clip(), files):
                write_npz(stage(f), arrays, what=f"clip {name!r}")
        where = files[0] if len(files) == 1 else Path(args.output)
        _say(args, f"wrote {where}: {len(names)} clip{'s' if len(names) != 1 else ''} as .npz, {export.num_frames} frames"
                   + (f", features {args.features} with statistics over all of them" if args.features else ""))
        return 0
    with MotionDatabase.open(args.database) as db:
        all_names = db.names
        names = [all_names[r] for r in select_rows(db, None if args.all else args.clips, skeletons)]
        files, folder = _export_targets(args, names, ".bvh", single_file=len(names) == 1 and not args.all)
        frames = 0
        with _all_or_nothing(args, folder) as stage:
            for b in range(0, len(names), 64):
                for m, f in zip(db.read_many(names[b:b + 64], dtype=torch.float64), files[b:b + 64]):
                    write_bvh(m, stage(f))
                    frames += m.num_frames
    if len(names) == 1:
        _say(args, f"wrote {files[0]}: {m.name}, {m.num_frames} frames at {m.fps:g} fps")
    else:
        _say(args, f"wrote {args.output}: {len(names)} clips as BVH, {frames} frames")
    return 0


# --------------------------------------------------------------------------------------------
# splice
# --------------------------------------------------------------------------------------------
def _db_spec(db, skeleton_id: int, skeleton):
    """The spec stored with a skeleton of the database, or one detected for it."""
    from .specs import DatasetSpec, detect_spec

    text = db.spec_json(skeleton_id)
    return DatasetSpec.from_json(text) if text else detect_spec(skeleton)


def _device(name: str | None):
    """A torch device name checked up front: one clear line instead of a traceback later."""
    from .job.config import check_device

    return check_device(name)


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {value}")
    return value


_MAX_FILMSTRIP = 64  # columns of a PNG filmstrip: more would not fit a screen (and took minutes and GBs)


def _bounded_int(lo: int, hi: int):
    """An argparse type: a whole number from ``lo`` to ``hi``."""
    def parse(text: str) -> int:
        value = _positive_int(text) if lo >= 1 else int(text)
        if not lo <= value <= hi:
            raise argparse.ArgumentTypeError(f"must be from {lo} to {hi}, got {value}")
        return value
    return parse


def _share(text: str) -> float:
    """argparse type: a number from 0 to 1."""
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not 0.0 <= value <= 1.0:
        raise argparse.ArgumentTypeError(f"must be a number from 0 to 1, got {text!r}")
    return value


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not (value > 0 and value < float("inf")):
        raise argparse.ArgumentTypeError(f"must be a positive number, got {text!r}")
    return value


def _splice_options(args):
    from .splice import AlignOptions, SpliceOptions

    return SpliceOptions(align=AlignOptions(max_run=args.max_run), posture=not args.no_posture,
                         force=args.force_locomotion, device=_device(args.device), timing=args.timing,
                         acting_limbs=_acting_limbs(args), twist=args.twist)


def _acting_limbs(args):
    from .splice.standing import parse_limbs

    try:
        return parse_limbs(args.acting_limbs)
    except ValueError as exc:
        raise TorchspliceError(f"--acting-limbs: {exc}") from None


def cmd_splice(args) -> int:
    import json as _json

    from .formats.bvh import write_bvh
    from .store.database import MotionDatabase
    from .splice import splice
    from .splice.references import find_reference
    from .splice.registry import get_method

    method = get_method(args.method)
    out = _output(args, "bvh", inputs=[args.database])
    with MotionDatabase.open(args.database) as db:
        loco, act, spec = _read_pair(db, args)
        ref = None
        if method.needs_reference:
            name = args.reference
            if name is None:
                t = db.table()
                cands = [(str(n), str(r), _json.loads(lab or "{}")) for n, r, lab in zip(t["name"], t["role"], t["labels"])]
                name = find_reference(act.name, act.labels, cands, spec)
            ref = db.read(name) if name is not None else None  # a standing action needs none
        elif args.reference is not None:
            raise TorchspliceError(f"--reference is only used by methods that need a reference clip (cpmc), not {method.name}")
    try:
        result = splice(loco, act, spec, method=method, reference=ref, options=_splice_options(args))
    except TorchspliceError as exc:
        if method.needs_reference and ref is None and "reference" in str(exc):
            raise TorchspliceError(f"no plain-locomotion reference found for action {act.name!r}: name one with "
                                   "--reference (or add a [clips.reference] rule to the spec)") from None
        raise
    with _locked(out, args):
        write_bvh(result.motion, out)
    extra = f", reference {result.reference}" if result.reference else ""
    if result.timing != "timewarp":
        acting = f"; acting limbs: {', '.join(result.acting) or 'none'}" if method.name == "splice" else ""
        detail = f"; standing action ({result.timing}{acting})"
    else:
        shown = [f"alignment cost {result.cost:.3g}" if "cost" in method.diagnostics else "",
                 f"action cropped by {result.crop} frames" if "crop" in method.diagnostics else "",
                 f"posture rotation {result.posture_deg:.1f} deg" if "posture" in method.diagnostics else ""]
        detail = "".join(f"{'; ' if not k else ', '}{t}" for k, t in enumerate(t for t in shown if t))
    _say(args, f"wrote {out}: {method.name} of {act.name} onto {loco.name}{extra}: {result.motion.num_frames} frames "
               f"at {result.motion.fps:g} fps{detail}")
    for note in result.notes:
        print(f"note: {note}", file=sys.stderr)
    if "cost" in method.diagnostics:
        from .job.plan import leg_length
        from .job.task import poor_alignment

        poor = poor_alignment(result.cost, leg_length(loco.skeleton, spec.bind(loco.skeleton)))
        if poor:
            print(f"note: {poor}: the two gaits match worse than 95% of walk-onto-walk pairs (whose median is "
                  f"0.05); check the result, or cut long takes with import --split", file=sys.stderr)
    return 0


def _add_pair_args(s) -> None:
    s.add_argument("database", help="motion database (.h5)")
    s.add_argument("--locomotion", required=True, metavar="NAME", help="clip giving root and lower body")
    s.add_argument("--action", required=True, metavar="NAME", help="clip giving the upper body")


def _add_output_flags(s, force_help: str = "overwrite an existing file", quiet_help: str = "print nothing on success") -> None:
    s.add_argument("-f", "--force", action="store_true", help=force_help)
    s.add_argument("-q", "--quiet", action="store_true", help=quiet_help)


def _add_splice_options(s, standing: bool = True) -> None:
    """The splice's flags; ``standing=False`` leaves out those about clips that do not locomote
    (plot-alignment always time-aligns)."""
    s.add_argument("--max-run", type=_positive_int, default=3, metavar="L",
                   help="slope limit of the timewarp: at most L frames of one clip while the other waits (default 3)")
    s.add_argument("--no-posture", action="store_true", help="skip posture transfer (splice method)")
    s.add_argument("--twist", type=_share, default=0.0, metavar="SHARE",
                   help="share (0 to 1) of the locomotion's torso twist that posture transfer adds, e.g. 0.5 on side "
                        "steps (splice method; default 0: the action's posture as it is)")
    if not standing:
        s.set_defaults(force_locomotion=True, timing="loop", acting_limbs="auto")
    else:
        _add_standing_options(s)
    s.add_argument("--device", default=None,
                   help="where the work runs: cpu (default: the compiled splicer) or a torch device such as cuda")


def _add_standing_options(s) -> None:
    s.add_argument("--force-locomotion", action="store_true",
                   help="time-align clips that do not locomote (the method's limit) instead of refusing a locomotion "
                        "that does not locomote and splicing a standing action by --timing")
    s.add_argument("--timing", choices=("loop", "hold", "fit"), default="loop",
                   help="how an action that does not locomote (a standing action: a wave, a bow) fills the locomotion: "
                        "loop: play it from its start and loop it (the loop holds the whole gesture) with a seamless "
                        "blend (default); hold: play it once and hold its last frame; fit: time-scale the whole action "
                        "to the locomotion's length (faster onto a shorter one). Onto a locomotion shorter than the "
                        "action, loop and hold play the window of the action where the acting arms move most")
    s.add_argument("--acting-limbs", default="auto", metavar="LIMBS",
                   help="the arms standing actions act with: auto (default: found from each clip's data), none, or "
                        "left_arm, right_arm or both; the other arm keeps the locomotion's swing (splice method)")


def cmd_plot_alignment(args) -> int:
    from .store.database import MotionDatabase
    from .viz.alignment import plot_alignment

    out = _output(args, "plot", inputs=[args.database])
    with MotionDatabase.open(args.database) as db:
        loco, act, spec = _read_pair(db, args)
    with _locked(out, args):
        plot_alignment(loco, act, spec, out, options=_splice_options(args))
    _say(args, f"wrote {out}: alignment of {act.name} to {loco.name}")
    return 0


def cmd_render(args) -> int:
    from .viz.render import render
    from .viz.sources import read_clips

    out = _output(args, "render", inputs=[args.database] + list(args.sources or []))
    clips, spec = read_clips(args.database, args.clips, sources=args.sources)
    longest = max(c.num_frames for c in clips)
    frames = args.frames
    if out.suffix.lower() == ".png" and frames > longest:
        print(f"note: --frames {frames} is more than the {longest} frames of the longest clip; drawing {longest}",
              file=sys.stderr)
        frames = longest
    with _locked(out, args):
        render(clips, out, titles=[c.name for c in clips], up_axis=spec.up_axis, frames=frames,
               max_seconds=args.max_seconds)
    _say(args, f"wrote {out}: {len(clips)} clip{'s' if len(clips) != 1 else ''}")
    return 0


def cmd_view(args) -> int:
    from .viz.viewer import viewer_notes, write_viewer

    out = _output(args, "viewer", inputs=[args.database] + list(args.sources or []))
    with _locked(out, args):
        got = write_viewer(args.database, out, clips=args.clips, sources=args.sources, max_clips=args.max_clips,
                           quiet=True)
    if not args.quiet:
        for line in viewer_notes(got, args.database, args.max_clips, _flag):
            print(line, file=sys.stderr)
    _say(args, f"wrote {out}: {len(got.names)} clip{'s' if len(got.names) != 1 else ''}, {got.size / 1e6:.1f} MB")
    return 0


def cmd_evaluate(args) -> int:
    from .evaluation.report import evaluate_database

    out = _output(args, "report", inputs=[args.database] + list(args.sources or []))
    with _locked(out, args):
        agg = evaluate_database(args.database, out, sources=args.sources, pictures=not args.no_pictures,
                                max_rows=args.max_rows)
    if not args.quiet:
        from .store.database import MotionDatabase

        with MotionDatabase.open(args.database) as db:
            u = db.attrs.get("units") or "units"
        u = "units" if u in ("mixed", "unknown") else u
        for method, a in agg.items():
            gt = f", ground-truth error {a['gt_error']:.2f} {u} over {a['gt_pairs']} pairs" if a["gt_error"] is not None else ""
            print(f"{method}: {a['clips']} clips, foot skate {a['foot_skate']:.2f} {u}/s, "
                  f"posture kept {a['posture']:.2f} {u}{gt}")
        print(f"wrote {out}")
    return 0


# --------------------------------------------------------------------------------------------
# splice-all
# --------------------------------------------------------------------------------------------
def cmd_splice_all(args) -> int:
    import logging

    from .job import SpliceJob, job_config
    from .job.config import parse_shard

    logging.basicConfig(level=getattr(logging, args.log_level.upper()), format="torchsplice: %(message)s", stream=sys.stderr)
    config = job_config(  # the options of torchsplice.job.splice_all, from the flags
        args.database, args.output, actions_db=Path(args.actions_db) if args.actions_db else None,
        locomotions=args.locomotions, actions=args.actions, methods=args.method, memory_budget_mb=args.memory_budget,
        batch_pairs=args.batch_size, force_locomotion=args.force_locomotion, copy_sources=args.copy_sources,
        max_run=args.max_run, max_length_ratio=args.max_length_ratio, timing=args.timing, acting_limbs=args.acting_limbs,
        posture=not args.no_posture, twist=args.twist, device=_device(args.device), compression=args.compression, layout=args.layout,
        engine=args.engine, workers=args.workers, ray_address=args.ray_address,
    )
    if args.ray_address and args.engine != "ray":
        raise TorchspliceError("--ray-address needs --engine ray")
    command = "torchsplice " + shlex.join(args.argv)
    shard = parse_shard(args.shard) if args.shard is not None else None  # --shard '' is a mistake, not no shard
    job = SpliceJob(config, progress=not args.quiet, restart=args.restart, overwrite=args.force, command=command, shard=shard,
                    dry_run=args.dry_run)
    try:
        summary = job.run()
    except KeyboardInterrupt as exc:
        print(f"torchsplice: {_stopped(exc)}; finished tasks are kept in {job.work}; "
              "run the same command again to resume", file=sys.stderr)
        return _stop_code(exc)
    if not args.quiet:
        print("\n".join(summary.lines(_flag)))
    return 0


def cmd_merge(args) -> int:
    from .job import merge_job

    summary = merge_job(Path(args.output), overwrite=args.force, progress=not args.quiet,
                        command="torchsplice " + shlex.join(args.argv))
    if not args.quiet:
        print("\n".join(summary.lines(_flag)))
    return 0


# --------------------------------------------------------------------------------------------
# parser and entry point
# --------------------------------------------------------------------------------------------
def _methods() -> tuple[str, ...]:
    """The registered methods, for --help and --method (the registry loads no torch)."""
    from .splice.registry import available_methods

    return available_methods()


def _plugins_in(argv: list[str]) -> list[str]:
    """The ``--plugin MODULE`` values of a command line, read before the parser is built (so that
    plug-in methods appear in its help)."""
    out = []
    for k, a in enumerate(argv):
        if a == "--plugin" and k + 1 < len(argv):
            out.append(argv[k + 1])
        elif a.startswith("--plugin="):
            out.append(a.split("=", 1)[1])
    return out


class _Parser(argparse.ArgumentParser):
    """argparse, with a usage mistake (a missing or malformed flag) said in one line, as every
    other error is, pointing at ``--help`` instead of printing the whole usage."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    from .job.engines import available_engines

    p = _Parser(
        prog="torchsplice",
        description="Splice upper-body actions onto locomotion for every pair of clips in a motion database.",
    )
    p.add_argument("--version", action="version", version=f"torchsplice {__version__}")
    p.add_argument("--plugin", action="append", metavar="MODULE", default=[],
                   help="import this module first: a plug-in that registers splicing methods or engines (repeatable; "
                        "also TORCHSPLICE_PLUGINS=MODULE[,MODULE...] and the torchsplice.methods entry point group)")
    sub = p.add_subparsers(dest="command", metavar="COMMAND", required=True)

    s = sub.add_parser("sample", help="write the built-in synthetic sample database (no data needed)",
                       description="Write the built-in sample: procedurally generated locomotions (straight walk, "
                                   "curve, sharp turn, side-step, jog) and actions performed while walking (carry a "
                                   "box, carry a cup, wave, punch, arms out) on a standard 22-joint skeleton.")
    s.add_argument("-o", "--output", required=True, help="database to write (.h5)")
    _add_output_flags(s)
    s.set_defaults(func=cmd_sample)

    s = sub.add_parser("import", help="import BVH files or folders into a motion database",
                       description="Import BVH files (folders are searched recursively) into one HDF5 motion "
                                   "database. A file that cannot be read is skipped with a one-line reason and "
                                   "the good files still land; the exit code is then 1.")
    s.add_argument("paths", nargs="+", metavar="PATH", help="BVH files or folders")
    s.add_argument("-o", "--output", required=True, help="database to write (.h5)")
    s.add_argument("--spec", default="auto",
                   help="dataset spec: a shipped name (bandai_namco, cmu, cmu_max, lafan1, sample, generic) or a "
                        ".toml path; 'auto' (default) picks per file")
    s.add_argument("--append", action="store_true", help="add to an existing database")
    s.add_argument("-f", "--force", action="store_true", help="overwrite an existing file")
    s.add_argument("--float64", action="store_true", help="store frames in float64 (default float32)")
    s.add_argument("--units", default=None, metavar="UNIT",  # checked by import_bvh before any work
                   help="convert every clip from its spec's units to these (m, cm, mm, in, ft; CMU's own unit is 'cmu'), "
                        "so that datasets in different units share one database; default: keep each file's units")
    s.add_argument("--split", type=_positive_float, default=None, metavar="SECONDS",
                   help="cut takes longer than 1.25 x SECONDS into windows of SECONDS (named NAME#000, NAME#001, ...; "
                        "labels split_from and split_frame say where each came from), so that long takes splice in reasonable "
                        "time and memory")
    s.add_argument("--split-overlap", type=float, default=1.0, metavar="SECONDS",
                   help="overlap of consecutive windows (default 1 s)")
    s.add_argument("-q", "--quiet", action="store_true", help="no progress bar or summary")
    s.set_defaults(func=cmd_import)

    s = sub.add_parser("info", help="list a database's clips, skeletons and roles",
                       description="Describe a motion database. With --json, print an object whose 'clips' list "
                                   "holds, per clip, name, frames, fps, duration_s, role, labels, skeleton, source.")
    s.add_argument("database", help="motion database (.h5)")
    s.add_argument("--json", action="store_true", help="machine-readable output")
    s.set_defaults(func=cmd_info)

    s = sub.add_parser("export", help="write clips of a database as BVH or NumPy .npz (for training and other tools)",
                       description="Write clips (by name, as `info` lists them, or --all) as BVH files with the "
                                   "skeleton's original channel layout, or as .npz: local rotations (WXYZ), root "
                                   "translation, trajectory, local translations, world positions, fps, joints, parents, "
                                   "offsets and labels (layout: torchsplice/formats/npz.py). -o is a file for one clip (or "
                                   "--packed), else a folder, one file per clip.")
    s.add_argument("database", help="motion database (.h5)")
    s.add_argument("clips", nargs="*", metavar="CLIP", help="clip names")
    s.add_argument("-o", "--output", required=True, help="file to write (one clip, --packed), or folder (several clips)")
    s.add_argument("--all", action="store_true", help="export every clip (or every clip of --skeleton)")
    s.add_argument("--format", choices=("bvh", "npz"), default=None,
                   help="bvh or npz (default: from -o's suffix; bvh for a folder unless --packed or --features)")
    s.add_argument("--packed", action="store_true",
                   help="npz: one file with every clip concatenated along frames and offsets[i]:offsets[i+1] "
                        "slicing clip i (clips of one skeleton topology)")
    s.add_argument("--features", choices=("6d",), default=None,
                   help="npz: add 6D rotations (Zhou et al. 2019), joint, root and trajectory velocities, and per-"
                        "dimension mean and std of every array over all exported clips, for normalisation")
    s.add_argument("--skeleton", default=None, metavar="K[,K...]",
                   help="only clips on these skeletons (ids as `info` lists them)")
    _add_output_flags(s)
    s.set_defaults(func=cmd_export)

    s = sub.add_parser("splice", help="splice one action onto one locomotion and write a BVH file",
                       description="Splice the upper body of an action clip onto the lower body of a locomotion clip "
                                   "of the same database (clip names as `info` lists them). Methods: splice (Heck, "
                                   "Kovar & Gleicher 2006: timewarp, spatial alignment, posture transfer), naive "
                                   "(per-bone upper-body replacement, no timewarp) and cpmc (differencing against a "
                                   "plain-locomotion reference of the action's performer, chosen by the spec's "
                                   "[clips.reference] rule or named with --reference).")
    _add_pair_args(s)
    s.add_argument("-o", "--output", required=True, help="BVH file to write")
    s.add_argument("--method", default="splice", choices=_methods(),
                   help="splicing method (default splice; plug-ins add more, see --plugin)")
    s.add_argument("--reference", metavar="NAME", help="plain-locomotion reference of the action (cpmc)")
    _add_splice_options(s)
    _add_output_flags(s)
    s.set_defaults(func=cmd_splice)

    s = sub.add_parser("plot-alignment", help="picture of one pair's time alignment (distance grid, DP path, curve)",
                       description="Draw the lower-body distance grid of a locomotion and an action as a heat map with "
                                   "the optimal DP path and the fitted alignment curve over it (Heck et al. 2006, "
                                   "Figure 3), and the per-frame pelvis correction angle below. PNG, PDF or SVG. "
                                   "Clips that do not locomote are time-aligned anyway, as splice --force-locomotion "
                                   "does (without it, splice fills the locomotion with a standing action by --timing).")
    _add_pair_args(s)
    s.add_argument("-o", "--output", required=True, help="picture to write (.png, .pdf, .svg)")
    _add_splice_options(s, standing=False)
    _add_output_flags(s)
    s.set_defaults(func=cmd_plot_alignment)

    s = sub.add_parser("render", help="stick-figure preview of clips side by side (GIF, MP4 or PNG filmstrip)",
                       description="Draw clips as stick figures side by side (e.g. locomotion, action, naive, spliced) "
                                   "from a fixed camera that follows each root, with clip names as titles and a "
                                   "ground grid. .gif and .mp4 (needs ffmpeg) animate; .png is a filmstrip.")
    s.add_argument("database", help="motion database (.h5)")
    s.add_argument("clips", nargs="+", metavar="CLIP", help="clip names")
    s.add_argument("-o", "--output", required=True, help="file to write (.gif, .mp4, .png)")
    s.add_argument("--frames", type=_bounded_int(1, _MAX_FILMSTRIP), default=8, metavar="N",
                   help=f"frames per clip in a PNG filmstrip (default 8, at most {_MAX_FILMSTRIP})")
    s.add_argument("--max-seconds", type=_positive_float, default=None, metavar="SECONDS", help="show at most this many seconds")
    s.add_argument("--sources", nargs="+", metavar="DB",
                   help="databases holding clips not in DATABASE, e.g. a spliced clip's locomotion and action "
                        "(default: the inputs its run record names)")
    _add_output_flags(s)
    s.set_defaults(func=cmd_render)

    s = sub.add_parser("view", help="one self-contained HTML page that plays clips in 3D in a browser",
                       description="Write an HTML file (no server, no network: three.js is inlined) that plays the "
                                   "database's clips side by side in 3D, with an orbit camera, a timeline and a "
                                   "picker filtered by role, method and label; a spliced clip shows with its "
                                   "locomotion, its action and the other methods' results in one click.")
    s.add_argument("database", help="motion database (.h5)")
    s.add_argument("clips", nargs="*", metavar="CLIP",
                   help="clips to include (with the sources and other methods of spliced ones); default: all, "
                        "up to --max-clips")
    s.add_argument("-o", "--output", required=True, help="page to write (.html)")
    s.add_argument("--sources", nargs="+", metavar="DB",
                   help="databases holding the spliced clips' locomotions and actions (default: as recorded)")
    s.add_argument("--max-clips", type=_positive_int, default=100, metavar="N",
                   help="at most this many clips when none are named (default 100, about 8 MB for 10 s clips)")
    _add_output_flags(s)
    s.set_defaults(func=cmd_view)

    s = sub.add_parser("evaluate", help="Markdown report judging a spliced database, per clip and per method",
                       description="Judge a database written by splice-all: foot skate, arm-leg phase coherence, "
                                   "posture kept, and error against captured ground truth where the spec declares "
                                   "it; per clip and per method, with pictures.")
    s.add_argument("database", help="database written by splice-all")
    s.add_argument("-o", "--output", required=True, help="report to write (.md); pictures go to <stem>_files/")
    s.add_argument("--sources", nargs="+", metavar="DB", help="databases holding the source clips (default: as recorded)")
    s.add_argument("--no-pictures", action="store_true", help="tables only")
    s.add_argument("--max-rows", type=_positive_int, default=60, metavar="N", help="per-clip rows per method (default 60)")
    _add_output_flags(s, force_help="overwrite an existing report")
    s.set_defaults(func=cmd_evaluate)

    s = sub.add_parser("splice-all", help="splice every selected locomotion x action pair into a new database",
                       description="The main job: splice the upper body of every selected action onto the lower body "
                                   "of every selected locomotion and write all results as a new motion database "
                                   "(same schema, plus provenance, alignment curve and quality figures per clip). "
                                   "SELECT: comma-separated alternatives, each a glob on clip names ('*walk*'), "
                                   "role:NAME or label:KEY=VALUE; a repeated flag must match too. Killed or "
                                   "interrupted, the same command resumes where it stopped.")
    s.add_argument("database", help="motion database with the locomotions (and actions)")
    s.add_argument("-o", "--output", required=True, help="database to write (.h5)")
    s.add_argument("--locomotions", action="append", metavar="SELECT",
                   help="clips giving the lower body (default: role:locomotion,role:both)")
    s.add_argument("--actions", action="append", metavar="SELECT",
                   help="clips giving the upper body (default: role:action,role:both)")
    s.add_argument("--actions-db", metavar="DB", help="take the actions from this database (same skeleton)")
    s.add_argument("--method", default="splice", metavar="M[,M...]",
                   help=f"{', '.join(_methods())}, or several comma-separated (default splice; plug-ins add "
                        "more, see --plugin)")
    s.add_argument("--memory-budget", type=_positive_int, default=1024, metavar="MB",
                   help="memory for one batch of pairs (default 1024 MB); sets the batch size")
    s.add_argument("--batch-size", type=_positive_int, default=None, metavar="N", help="pairs per batch (overrides the budget)")
    s.add_argument("--copy-sources", action="store_true", help="copy the source clips into the output too")
    s.add_argument("--max-length-ratio", type=_positive_float, default=None, metavar="R",
                   help="skip pairs whose longer clip lasts more than R times the shorter (e.g. 3); long takes are "
                        "better cut with import --split")
    s.add_argument("--engine", default="local", choices=list(available_engines()),
                   help="local: worker processes on this machine (default); ray: Ray tasks on a cluster; or an engine "
                        "a --plugin module registers")
    s.add_argument("--workers", type=_positive_int, default=None, metavar="N",
                   help="local worker processes, one compute thread each (default: one per core); results do not depend on it")
    s.add_argument("--ray-address", default=None, metavar="HOST:PORT",
                   help="the Ray cluster to run on (with --engine ray; default: start a local Ray instance)")
    s.add_argument("--shard", default=None, metavar="K/N",
                   help="run only the K-th of N slices of the job's tasks into its work folder, and write no output "
                        "(for Slurm arrays, CI matrices); then run 'torchsplice merge OUT'")
    s.add_argument("--layout", default="copy", choices=["copy", "virtual"],
                   help="copy: one self-contained output file (default); virtual: the output's frames are HDF5 virtual "
                        "datasets over the task shards, kept in OUT.shards/ beside it (no copy, for outputs too large to copy)")
    s.add_argument("--compression", default="auto", choices=["auto", "lzf", "gzip", "none"],
                   help="compression of the output: auto (default: LZF on translations and per-frame columns, "
                        "rotations raw; fast, read by h5py), lzf (everything), gzip (smallest, read by every "
                        "HDF5 tool, several times slower to write) or none")
    _add_splice_options(s)
    s.add_argument("-f", "--force", action="store_true", help="overwrite an existing output file")
    s.add_argument("--restart", action="store_true", help="discard an unfinished earlier run instead of resuming it")
    s.add_argument("--dry-run", action="store_true",
                   help="plan only: say how many pairs would be spliced and skipped, the output's expected size and "
                        "the free space, and write nothing")
    s.add_argument("-q", "--quiet", action="store_true", help="no progress bar or summary")
    s.add_argument("--log-level", default="warning", choices=["debug", "info", "warning", "error"],
                   help="detail of log messages on stderr (default warning)")
    s.set_defaults(func=cmd_splice_all)

    s = sub.add_parser("merge", help="write a splice-all output from its finished shards (after --shard runs)",
                       description="Join the shards of a splice-all job, in plan order, into its output; says which "
                                   "slices are missing if some are.")
    s.add_argument("output", help="the output the job was run with (-o of splice-all)")
    _add_output_flags(s, force_help="overwrite an existing output")
    s.set_defaults(func=cmd_merge)
    return p


class Terminated(KeyboardInterrupt):
    """SIGTERM (a scheduler or ``kill`` stopping the process): handled like Ctrl-C."""


_SIGTERM_SEEN = [False]  # a SIGTERM arrived (libraries such as Ray re-raise it as a plain KeyboardInterrupt)


def _on_sigterm(signum, frame):
    _SIGTERM_SEEN[0] = True
    raise Terminated()


def _terminated(exc: BaseException) -> bool:
    return isinstance(exc, Terminated) or _SIGTERM_SEEN[0]


def _stopped(exc: BaseException) -> str:
    return "terminated" if _terminated(exc) else "interrupted"


def _stop_code(exc: BaseException) -> int:
    return 143 if _terminated(exc) else 130


def _one_line_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """``warnings.showwarning`` for the command line: ``torchsplice: warning: ...``, one line."""
    print(f"torchsplice: warning: {_one_line(message, limit=1000)}", file=file or sys.stderr)


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit code."""
    import signal
    import threading

    argv = list(sys.argv[1:] if argv is None else argv)
    try:
        from .splice.registry import load_plugins

        load_plugins(_plugins_in(argv))
        parser = build_parser()
    except TorchspliceError as exc:
        print(f"torchsplice: error: {_one_line(cli_message(exc), limit=1000)}", file=sys.stderr)
        return 2
    args = parser.parse_args(argv)
    args.argv = argv
    if getattr(args, "output", None) == "":  # an empty name would mean the current folder
        print("torchsplice: error: the output name is empty; name a file or folder", file=sys.stderr)
        return 2
    if args.func is cmd_splice_all and not args.dry_run:  # the workers load torch while this process plans
        from .job.engines.forkserver import prestart

        prestart(args.engine, args.workers, args.device)
    previous = None
    if threading.current_thread() is threading.main_thread():
        _SIGTERM_SEEN[0] = False
        previous = signal.signal(signal.SIGTERM, _on_sigterm)  # stop as Ctrl-C does: outputs discarded, work kept
    try:
        with warnings.catch_warnings():
            warnings.showwarning = _one_line_warning  # the library's warnings as one line each
            return args.func(args)
    except TorchspliceError as exc:
        print(f"torchsplice: error: {_one_line(cli_message(exc), limit=1000)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as exc:
        print(f"torchsplice: {_stopped(exc)}", file=sys.stderr)
        return _stop_code(exc)
    except BrokenPipeError:
        return 0
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


if __name__ == "__main__":
    sys.exit(main())
