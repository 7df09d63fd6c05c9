"""The n x m job: ``splice-all`` (splice every selected pair into a new database, resumable,
on local workers, a Ray cluster or a plug-in engine, or one ``--shard`` of it) and ``merge``
(join the shards of ``--shard`` runs). The flags are :class:`~torchsplice.job.config.JobConfig`'s
fields, with its defaults (declared in :mod:`torchsplice.job.defaults`); the engines and layouts
are the library's."""

from __future__ import annotations

import argparse

import sys
from pathlib import Path

from .base import Command, register_command
from .common import add_output_flags, command_line, device, flag, positive_float, positive_int, stop_code, stopped
from .splice import add_splice_options, methods
from ..core.errors import TorchspliceError
from ..core.names import counted
from ..job.defaults import (DEFAULT_ACTIONS, DEFAULT_ACTIONS_DB, DEFAULT_BATCH_PAIRS, DEFAULT_COMPRESSION,
                            DEFAULT_COPY_SOURCES, DEFAULT_ENGINE, DEFAULT_INDEX, DEFAULT_KEEP_HANDS_OUT, DEFAULT_LAYOUT,
                            DEFAULT_LOCOMOTIONS, DEFAULT_MAX_LENGTH_RATIO, DEFAULT_MEMORY_BUDGET_MB, DEFAULT_METHODS,
                            DEFAULT_RAY_ADDRESS, DEFAULT_RETARGET, DEFAULT_STORE, DEFAULT_TARGET, DEFAULT_WORKERS,
                            LAYOUTS, STORES)
from ..retarget.defaults import DEFAULT_FIX_FEET
from ..store.defaults import COMPRESSIONS

LOG_LEVELS = ("debug", "info", "warning", "error")  # --log-level: the logging levels worth choosing


def compressions() -> tuple[str, ...]:
    """``--compression`` choices: the database's compressions (``None`` spelt ``none``), the job's default first."""
    default = DEFAULT_COMPRESSION
    names = ["none" if c is None else c for c in COMPRESSIONS]
    return tuple(sorted(names, key=lambda c: c != ("none" if default is None else default)))


class SpliceAll(Command):
    name = "splice-all"
    help = "splice every selected locomotion x action pair into a new database"
    description = ("The main job: splice the upper body of every selected action onto the lower body of every "
                   "selected locomotion and write all results as a new motion database (same schema, plus "
                   "provenance, alignment curve and quality figures per clip). SELECT: comma-separated alternatives, "
                   "each a glob on clip names ('*walk*'), role:NAME or label:KEY=VALUE; a repeated flag must match "
                   "too. Killed or interrupted, the same command resumes where it stopped.")

    def add_arguments(self, s) -> None:
        from ..job.engines.registry import available_engines

        method = ",".join(DEFAULT_METHODS)
        budget = DEFAULT_MEMORY_BUDGET_MB
        engine = DEFAULT_ENGINE
        s.add_argument("database", help="motion database with the locomotions (and actions)")
        s.add_argument("-o", "--output", required=True, help="database to write (.h5)")
        s.add_argument("--locomotions", action="append", metavar="SELECT",
                       help=f"clips giving the lower body (default: {' '.join(DEFAULT_LOCOMOTIONS)})")
        s.add_argument("--actions", action="append", metavar="SELECT",
                       help=f"clips giving the upper body (default: {' '.join(DEFAULT_ACTIONS)})")
        s.add_argument("--actions-db", metavar="DB", default=DEFAULT_ACTIONS_DB,
                       help="take the actions from this database (any humanoid skeleton: see --retarget)")
        s.add_argument("--retarget", action=argparse.BooleanOptionalAction, default=DEFAULT_RETARGET,
                       help="form the pairs whose clips are on different skeletons (other joints or units) by "
                            "retargeting the action onto the locomotion's skeleton, once per action and skeleton "
                            "(default: on; --no-retarget skips those pairs)")
        s.add_argument("--fix-feet", action=argparse.BooleanOptionalAction, default=DEFAULT_FIX_FEET,
                       help="when retargeting, hold each foot where the source's stands (default: on)")
        s.add_argument("--target", default=DEFAULT_TARGET, metavar="TARGET",
                       help="bring every clip onto this skeleton first (other.h5, other.h5:K, a .bvh file, or smpl22), "
                            "into OUT.target-locomotions.h5 (and OUT.target-actions.h5) beside the output, made once "
                            "and reused by reruns")
        s.add_argument("--method", default=method, metavar="M[,M...]",
                       help=f"{', '.join(methods())}, or several comma-separated (default {method}; plug-ins add "
                            "more, see --plugin)")
        s.add_argument("--memory-budget", type=positive_int, default=budget, metavar="MB",
                       help=f"memory for one batch of pairs (default {budget} MB); sets the batch size")
        s.add_argument("--batch-size", type=positive_int, default=DEFAULT_BATCH_PAIRS, metavar="N",
                       help="pairs per batch (overrides the budget)")
        s.add_argument("--copy-sources", action="store_true", default=DEFAULT_COPY_SOURCES,
                       help="copy the source clips into the output too")
        s.add_argument("--no-index", dest="index", action="store_false", default=DEFAULT_INDEX,
                       help="write no OUT.h5.index.csv beside the output (by default: every clip's cost, flags, coverage, "
                            "labels and split by source clip, as info --csv and the exports give them; gzip-compressed, "
                            "OUT.h5.index.csv.gz, for more clips than a spreadsheet opens)")
        s.add_argument("--max-length-ratio", type=positive_float, default=DEFAULT_MAX_LENGTH_RATIO, metavar="R",
                       help="skip pairs whose longer clip lasts more than R times the shorter (e.g. 3); long takes are "
                            "better cut with import --split")
        s.add_argument("--engine", default=engine, choices=list(available_engines()),
                       help="local: worker processes on this machine (default); ray: Ray tasks on a cluster; or an engine "
                            "a --plugin module registers")
        s.add_argument("--workers", type=positive_int, default=DEFAULT_WORKERS, metavar="N",
                       help="local worker processes, one compute thread each (default: one per core); results do not "
                            "depend on it")
        s.add_argument("--ray-address", default=DEFAULT_RAY_ADDRESS, metavar="HOST:PORT",
                       help="the Ray cluster to run on (with --engine ray; default: start a local Ray instance)")
        s.add_argument("--shard", default=None, metavar="K/N",
                       help="run only the K-th of N slices of the job's tasks into its work folder, and write no output "
                            "(for Slurm arrays, CI matrices); then run 'torchsplice merge OUT'")
        s.add_argument("--layout", default=DEFAULT_LAYOUT, choices=list(LAYOUTS),
                       help="copy: one self-contained output file (default); virtual: the output's frames are HDF5 "
                            "virtual datasets over the task shards, kept in OUT.shards/ beside it (no copy, for "
                            "outputs too large to copy)")
        s.add_argument("--store", default=DEFAULT_STORE, choices=list(STORES),
                       help="motion: each spliced clip's frames (default); alignment: each source clip once and per "
                            "spliced clip what splicing computed (alignment curve, pelvis rotation), about a tenth of "
                            "the disk; every reader assembles the motions, bit for bit the same ('torchsplice "
                            "materialize' writes them out)")
        s.add_argument("--compression", default=DEFAULT_COMPRESSION or "none", choices=list(compressions()),
                       help="compression of the output: auto (default: LZF on translations and per-frame columns, "
                            "rotations raw; fast, read by h5py), lzf (everything), gzip (smallest, read by every "
                            "HDF5 tool, several times slower to write) or none")
        add_splice_options(s)
        s.add_argument("--no-keep-hands-out", dest="keep_hands_out", action="store_false",
                       default=DEFAULT_KEEP_HANDS_OUT,
                       help="write each splice as it comes, even where it puts a hand or forearm inside the body "
                            "deeper than its sources do (by default the arm is moved out by IK on the shoulder and "
                            "elbow, and the corrected_frames column counts the frames changed)")
        s.add_argument("--restart", action="store_true", help="discard an unfinished earlier run instead of resuming it")
        s.add_argument("--dry-run", action="store_true",
                       help="plan only: say how many pairs would be spliced and skipped, the output's expected size and "
                            "the free space, and write nothing")
        add_output_flags(s, force_help="overwrite an existing output file", quiet_help="no progress bar or summary")
        s.add_argument("--log-level", default="warning", choices=list(LOG_LEVELS),
                       help="detail of log messages on stderr (default warning)")

    def prepare(self, args) -> None:
        if not args.dry_run:  # the workers load torch while this process plans
            from ..job.engines.forkserver import prestart

            prestart(args.engine, args.workers, args.device, args.backend)

    def run(self, args) -> int:
        import logging

        from ..job import SpliceJob, job_config
        from ..job.config import parse_shard

        logging.basicConfig(level=getattr(logging, args.log_level.upper()), format="torchsplice: %(message)s",
                            stream=sys.stderr)
        config = job_config(  # the options of torchsplice.job.splice_all, from the flags
            args.database, args.output, actions_db=Path(args.actions_db) if args.actions_db else None,
            locomotions=args.locomotions, actions=args.actions, methods=args.method, memory_budget_mb=args.memory_budget,
            batch_pairs=args.batch_size, force_locomotion=args.force_locomotion, copy_sources=args.copy_sources,
            max_run=args.max_run, max_length_ratio=args.max_length_ratio, timing=args.timing,
            acting_limbs=args.acting_limbs, posture=not args.no_posture, twist=args.twist, keep_hands_out=args.keep_hands_out,
            device=device(args.device),
            compression=args.compression, layout=args.layout, store=args.store, engine=args.engine, workers=args.workers,
            ray_address=args.ray_address, backend=args.backend, retarget=args.retarget, fix_feet=args.fix_feet,
            target=args.target, index=args.index,
        )
        if args.ray_address and args.engine != "ray":
            raise TorchspliceError("--ray-address needs --engine ray")
        shard = parse_shard(args.shard) if args.shard is not None else None  # --shard '' is a mistake, not no shard
        job = SpliceJob(config, progress=not args.quiet, restart=args.restart, overwrite=args.force,
                        command=command_line(args), shard=shard, dry_run=args.dry_run)
        try:
            summary = job.run()
        except KeyboardInterrupt as exc:
            print(f"torchsplice: {stopped(exc)}; finished tasks are kept in {job.work}; "
                  "run the same command again to resume", file=sys.stderr)
            return stop_code(exc)
        if not args.quiet:
            print("\n".join(summary.lines(flag)))
        return 0


class Merge(Command):
    name = "merge"
    help = "write a splice-all output from its finished shards (after --shard runs)"
    description = ("Join the shards of a splice-all job, in plan order, into its output; says which slices are "
                   "missing if some are.")

    def add_arguments(self, s) -> None:
        s.add_argument("output", help="the output the job was run with (-o of splice-all)")
        s.add_argument("--no-index", dest="index", action="store_false", default=DEFAULT_INDEX,
                       help="write no OUT.h5.index.csv beside the output")
        add_output_flags(s, force_help="overwrite an existing output")

    def run(self, args) -> int:
        from ..job import merge_job

        summary = merge_job(Path(args.output), overwrite=args.force, progress=not args.quiet,
                            command=command_line(args), index=args.index)
        if not args.quiet:
            print("\n".join(summary.lines(flag)))
        return 0


class Materialize(Command):
    name = "materialize"
    help = "write the motions of an alignment store (splice-all --store alignment) as an ordinary database"
    description = ("Assemble every clip of an alignment store and write them as a motion store: the same clips, "
                   "table and columns, bit for bit what splice-all --store motion writes for the same job. Streams "
                   "in bounded memory.")

    def add_arguments(self, s) -> None:
        s.add_argument("database", help="the alignment store (.h5)")
        s.add_argument("-o", "--output", required=True, help="the motion store to write (.h5)")
        s.add_argument("--no-index", dest="index", action="store_false", default=DEFAULT_INDEX,
                       help="write no OUT.h5.index.csv beside the output")
        add_output_flags(s, force_help="overwrite an existing output")

    def run(self, args) -> int:
        from ..job.materialize import materialize

        n = materialize(args.database, args.output, overwrite=args.force, progress=not args.quiet, index=args.index)
        if not args.quiet:
            print(f"wrote {args.output}: {counted(n, 'clip')}")
        return 0


register_command(SpliceAll())
register_command(Merge())
register_command(Materialize())
