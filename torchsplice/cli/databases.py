"""Commands that make and describe databases: ``sample``, ``import`` and ``info``."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from .base import Command, register_command
from .common import add_output_flags, at, n, output, positive_float, progress, say
from ..formats.defaults import (DEFAULT_FILE_UNITS, DEFAULT_IMPORT_FORMAT, DEFAULT_IMPORT_WINDOW,
                                DEFAULT_IMPORT_WINDOW_OVERLAP, DEFAULT_NAME_PREFIX, DEFAULT_SPEC, DEFAULT_UNITS,
                                IMPORT_FORMATS)


class Sample(Command):
    name = "sample"
    help = "write the built-in synthetic sample database (no data needed)"
    description = ("Write the built-in sample: procedurally generated locomotions (straight walk, curve, sharp turn, "
                   "side-step, jog) and actions performed while walking (carry a box, carry a cup, wave, punch, arms "
                   "out) on a standard 22-joint skeleton.")

    def add_arguments(self, s) -> None:
        s.add_argument("-o", "--output", required=True, help="database to write (.h5)")
        add_output_flags(s)

    def run(self, args) -> int:
        from ..formats.sample_database import write_sample

        motions = write_sample(output(args, "database"), overwrite=args.force)
        frames = sum(m.num_frames for m in motions)
        roles = {}
        for m in motions:
            roles[m.role] = roles.get(m.role, 0) + 1
        say(args, f"wrote {args.output}: {len(motions)} synthetic clips ({frames} frames at 30 fps), "
                  + ", ".join(f"{k} {r}" for r, k in sorted(roles.items())))
        return 0


class Import(Command):
    name = "import"
    help = "import BVH files or folders (or HumanML3D folders) into a motion database"
    description = ("Import BVH files (folders are searched recursively) into one HDF5 motion database; a HumanML3D "
                   "folder (one holding new_joint_vecs/) gives its motions on the SMPL body at 20 fps, their captions "
                   "kept as the clips' captions label. A file that cannot be read is skipped with a one-line reason "
                   "and the good files still land; the exit code is then 1.")

    def add_arguments(self, s) -> None:
        spec = DEFAULT_SPEC
        s.add_argument("paths", nargs="+", metavar="PATH", help="BVH files or folders, or HumanML3D folders")
        s.add_argument("--format", choices=IMPORT_FORMATS, default=DEFAULT_IMPORT_FORMAT,
                       help="what the paths hold: auto (default: a folder holding new_joint_vecs/ is HumanML3D, the "
                            "rest BVH), bvh or humanml3d")
        s.add_argument("-o", "--output", required=True, help="database to write (.h5)")
        s.add_argument("--spec", default=spec,
                       help="dataset spec: a shipped name (bandai_namco, cmu, cmu_max, lafan1, sample, generic) or a "
                            f".toml path; {spec!r} (default) picks per file")
        s.add_argument("--append", action="store_true", help="add to an existing database")
        s.add_argument("--float64", action="store_true", help="store frames in float64 (default float32)")
        s.add_argument("--units", default=DEFAULT_UNITS, metavar="UNIT",  # checked by import_bvh
                       help="convert every clip from its spec's units to these (m, cm, mm, in, ft; CMU's own unit is "
                            "'cmu'), so that datasets in different units share one database; default: keep each "
                            "file's units")
        s.add_argument("--file-units", default=DEFAULT_FILE_UNITS, metavar="UNIT",
                       help="the units the files are in, where their spec does not say (the generic spec: joints "
                            "guessed): recorded, and converted by --units")
        s.add_argument("--name-prefix", default=DEFAULT_NAME_PREFIX, metavar="PREFIX",
                       help="put PREFIX before every clip's name, so that sources with the same file names (two "
                            "HumanML3D folders) share a database")
        s.add_argument("--window", type=positive_float, default=DEFAULT_IMPORT_WINDOW, metavar="SECONDS",
                       help="cut takes longer than 1.25 x SECONDS into windows of SECONDS (named NAME#000, NAME#001, "
                            "...; labels split_from and split_frame say where each came from), so that long takes "
                            "splice in reasonable time and memory (train/val/test splits are the exports' "
                            "--split-ratios)")
        overlap = DEFAULT_IMPORT_WINDOW_OVERLAP
        s.add_argument("--window-overlap", type=float, default=overlap, metavar="SECONDS",
                       help=f"overlap of consecutive windows (default {overlap:g} s)")
        # the earlier names, kept working for scripts that use them (unlisted: "split" is train/val/test)
        s.add_argument("--split", dest="window", type=positive_float, default=argparse.SUPPRESS, help=argparse.SUPPRESS)
        s.add_argument("--split-overlap", dest="window_overlap", type=float, default=argparse.SUPPRESS,
                       help=argparse.SUPPRESS)
        add_output_flags(s, quiet_help="no progress bar or summary")

    def run(self, args) -> int:
        from ..formats.importer import NothingImportedError, import_bvh

        def skipped_lines(skipped):
            groups: dict[str, list[str]] = {}  # a wrong --spec on a folder is one mistake: one line for its files
            for f, why in skipped:
                groups.setdefault(why, []).append(f)
            for why, files in groups.items():
                if len(files) == 1 or not _spec_misfit(args.spec, why):  # any other bad file: its own line
                    for f in files:
                        print(f"skipped {at(f, why)}", file=sys.stderr)
                    continue
                shown = ", ".join(Path(f).name for f in files[:2]) + (", ..." if len(files) > 2 else "")
                print(f"skipped {len(files)} files ({shown} in {Path(files[0]).parent}): {why}"
                      + _auto_spec_hint(args.spec, files[0], why), file=sys.stderr)

        try:
            report = import_bvh(args.paths, args.output, spec=args.spec, append=args.append, overwrite=args.force,
                                float64=args.float64, window=args.window, window_overlap=args.window_overlap,
                                units=args.units, progress=lambda it, total, desc: progress(it, total, desc, args.quiet),
                                format=args.format, file_units=args.file_units, name_prefix=args.name_prefix)
        except NothingImportedError as exc:
            skipped_lines(exc.report.skipped)
            raise
        for g in report.guessed:
            say(args, f"skeleton {g.skeleton} (first seen in {g.path}): joint roles guessed by the {g.spec!r} spec "
                      "(check them; a dataset spec fixes them):\n" + "\n".join(f"  {ln}" for ln in g.summary))
        cut = report.cut
        # a cut take is one file but several clips: count the clips written, and the files when they differ
        added = sum(c.windows for c in report.imported)
        files = f" from {n(len(report.imported), 'file')}" if added != len(report.imported) else ""
        say(args, f"imported {n(added, 'clip')}{files} ({report.frames} frames) into {args.output} "
                  f"({n(report.clips, 'clip')} in all)"
                  + (f"; {n(len(cut), 'long take')} cut into {sum(c.windows for c in cut)} windows of {args.window:g} s"
                     if cut else ""))
        for f, why in report.warnings:
            print(f"warning: {at(f, why)}", file=sys.stderr)
        skipped_lines(report.skipped)
        if report.skipped:
            print(f"{len(report.skipped)} input(s) skipped, {len(report.imported)} imported", file=sys.stderr)
        return 1 if report.skipped else 0


def _spec_misfit(spec, why: str) -> bool:
    """Whether a file was skipped because the ``--spec`` asked for does not fit it."""
    return spec not in (None, "auto") and ".toml:" in why  # a spec's errors name its file


def _auto_spec_hint(spec, path, why: str) -> str:
    """``"; --spec auto picks 'bandai_namco' for them"`` when files were skipped because the
    ``--spec`` asked for does not fit them and a shipped spec does, else ``""``."""
    if not _spec_misfit(spec, why):
        return ""
    try:
        from ..formats.bvh import read_bvh
        from ..specs import detect_spec

        picked = detect_spec(read_bvh(path).skeleton, Path(path).name)
    except Exception:  # only a hint: the skip's own reason stands
        return ""
    return f"; --spec auto picks {picked.name!r} for them" if picked.name != spec else ""


STORE_WORDS = {"motion": "each clip's frames are stored",
               "alignment": "the source clips once and what splicing computed; every read assembles the motions, "
                            "`torchsplice materialize` writes them as a motion store"}
"""What ``info`` says of each kind of store (:mod:`torchsplice.store.assembly`)."""


def _labels_text(labels: dict, limit: int = 60) -> str:
    """Labels on one line: a long or multi-line value (captions) by its first line, cut."""
    def short(k: str, v: str) -> str:
        v = str(v)
        first = v.split("\n", 1)[0]
        if k.split(".")[-1] == "captions":  # HumanML3D lines: the caption, without its tokens
            first = first.split("#", 1)[0]
        return (first[:limit] + "...") if first != v or len(first) > limit else first

    return " ".join(f"{k}={short(k, v)}" for k, v in sorted(labels.items()))


class Info(Command):
    name = "info"
    help = "list a database's clips, skeletons and roles"
    description = ("Describe a motion database: its kind of store (motion: each clip's frames; alignment: the source "
                   "clips once and what splicing computed, assembled into motions where read), skeletons, roles and "
                   "clips. With --json, print an object whose 'store' is 'motion' or 'alignment' and whose 'clips' "
                   "list holds, per clip, name, frames, fps, duration_s, role, labels, skeleton, source.")

    def add_arguments(self, s) -> None:
        s.add_argument("database", help="motion database (.h5)")
        s.add_argument("clips", nargs="*", metavar="CLIP",
                       help="only these clips: names, or selectors ('role:spliced', 'method:naive', 'walk_*')")
        s.add_argument("--select", action="append", metavar="SELECT", default=None,
                       help="only clips this selector selects (repeat: all of them)")
        s.add_argument("--limit", type=int, default=None, metavar="N",
                       help="list at most N clips (the rest counted); default all (--json: all)")
        s.add_argument("--json", action="store_true", help="machine-readable output")
        s.add_argument("--csv", metavar="FILE", default=None,
                       help="also write the (selected) clips' table as CSV: every column, a spliced clip's cost, "
                            "alignment_distance, flags, coverage...; labels as JSON")

    def run(self, args) -> int:
        from ..store.database import MotionDatabase

        if args.csv is not None:
            from ..store.atomic import check_output

            check_output(args.csv, (".csv",), "a CSV file", inputs=[args.database], overwrite=True)
        with MotionDatabase.open(args.database) as db:
            s = {**db.summary(clips=args.clips, select=args.select), "store": db.store}
        if args.csv is not None:
            from ..formats.index import write_rows_csv

            write_rows_csv(args.csv, s["clips"])
        if args.json:
            print(json.dumps(s, indent=2))
            return 0
        minutes = s["duration_s"] / 60
        print(f"{s['path']}: {n(s['num_clips'], 'clip')}, {s['num_frames']} frames ({minutes:.1f} min); "
              f"schema {s['schema_version']}, units {s['units'] or '?'}, up axis {s['up_axis'] or '?'}, "
              f"quaternions {s['quaternion_order']}")
        print(f"store: {s['store']} ({STORE_WORDS.get(s['store'], '?')})")
        for k in s["skeletons"]:
            print(f"skeleton {k['id']}: {k['joints']} joints, root {k['root']}, spec {k['spec'] or '-'}"
                  f"{' (roles guessed)' if k['guessed_roles'] else ''}, units {k['units'] or '?'}, "
                  f"up axis {k['up_axis'] or '?'}, {n(k['clips'], 'clip')}")
        print("roles: " + ", ".join(f"{r} {k}" for r, k in sorted(s["roles"].items())))
        run = s.get("run")
        if isinstance(run, dict):
            print(f"run: {run.get('command', '?')} ({run.get('tool', 'torchsplice')}, started {run.get('started', '?')})")
        if s["clips"]:
            w = max(4, max(len(c["name"]) for c in s["clips"]))
            print(f"{'name':<{w}}  {'frames':>6}  {'fps':>5}  {'sec':>6}  {'role':<10}  labels")
            shown = s["clips"] if args.limit is None else s["clips"][:max(args.limit, 0)]
            for c in shown:
                print(f"{c['name']:<{w}}  {c['frames']:>6}  {c['fps']:>5g}  {c['duration_s']:>6.2f}  "
                      f"{c['role'] or '-':<10}  {_labels_text(c['labels'])}")
            if len(shown) < len(s["clips"]):
                print(f"... {len(s['clips']) - len(shown)} more clips (--limit; select some with CLIP or --select)")
        return 0


register_command(Sample())
register_command(Import())
register_command(Info())
