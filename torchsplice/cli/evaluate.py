"""``evaluate``: the Markdown report judging a spliced database, per clip and per method."""

from __future__ import annotations

import math

from .base import Command, register_command
from .common import add_output_flags, locked, n, output, positive_int, progress
from ..evaluation.defaults import DEFAULT_MAX_ROWS, DEFAULT_PICTURES


class Evaluate(Command):
    name = "evaluate"
    help = "Markdown report judging a spliced database, per clip and per method"
    description = ("Judge a database written by splice-all: foot skate, arm-leg phase coherence, posture kept, and "
                   "error against captured ground truth where the spec declares it; per clip and per method, with "
                   "pictures.")

    def add_arguments(self, s) -> None:
        max_rows = DEFAULT_MAX_ROWS
        s.add_argument("database", help="database written by splice-all")
        s.add_argument("-o", "--output", required=True, help="report to write (.md); pictures go to <stem>_files/")
        s.add_argument("--sources", nargs="+", metavar="DB", help="databases holding the source clips (default: as recorded)")
        s.add_argument("--no-pictures", action="store_true", default=not DEFAULT_PICTURES,
                       help="tables only")
        s.add_argument("--max-rows", type=positive_int, default=max_rows, metavar="N",
                       help=f"per-clip rows per method in the report (default {max_rows}; --csv and --json hold every row)")
        s.add_argument("--select", action="append", metavar="SELECT", default=None,
                       help="only the spliced clips this selector selects (repeat: all of them), e.g. method:splice")
        s.add_argument("--csv", metavar="FILE", default=None, help="also write every clip's row as CSV, for scripts")
        s.add_argument("--json", metavar="FILE", default=None,
                       help="also write the aggregates and every clip's row as JSON, for scripts")
        add_output_flags(s, force_help="overwrite an existing report")

    def run(self, args) -> int:
        from ..evaluation.report import evaluate_database

        from ..store.atomic import check_output

        out = output(args, "report")
        tables = [None if f is None else check_output(f, (suffix,), what, inputs=[args.database, out], overwrite=args.force)
                  for f, suffix, what in ((args.csv, ".csv", "a CSV file"), (args.json, ".json", "a JSON file"))]
        with locked(out, args):
            agg = evaluate_database(args.database, out, sources=args.sources, pictures=not args.no_pictures,
                                    max_rows=args.max_rows, csv=tables[0], json=tables[1], select=args.select,
                                    progress=lambda it, total, desc: progress(it, total, desc, args.quiet, unit="batch"))
        if not args.quiet:
            from ..store.database import MotionDatabase

            with MotionDatabase.open(args.database) as db:
                u = db.attrs.get("units") or "units"
            u = "units" if u in ("mixed", "unknown") else u

            def fig(v) -> str:  # a figure that is missing or not finite (a result's huge values) prints as -
                return f"{v:.2f}" if isinstance(v, (int, float)) and math.isfinite(v) else "-"

            for method, a in agg.items():
                gt = (f", ground-truth error {fig(a['gt_error'])} {u} over {a['gt_pairs']} pairs"
                      if a.get("gt_error") is not None else "")
                print(f"{method}: {n(a['clips'], 'clip')}, foot speed in contact {fig(a.get('foot_speed_in_contact'))} {u}/s, "
                      f"posture kept {fig(a.get('posture'))} {u}{gt}")
            print(f"wrote {out}" + "".join(f", {t}" for t in tables if t is not None))
        return 0


register_command(Evaluate())
