"""``mirror``: clips of a database and their mirror images (left and right swapped), written as a
new database: data augmentation on any skeleton with a left/right map.

The command parses its flags and calls :func:`torchsplice.retarget.mirror.mirror_clips`, which
does the rest exactly as from Python.
"""

from __future__ import annotations

import argparse

from .base import Command, register_command
from .common import add_clip_arguments, add_output_flags, chosen_clips, command_line, output, progress, say
from ..retarget.defaults import DEFAULT_ORIGINALS


class Mirror(Command):
    name = "mirror"
    help = "clips and their mirror images (left and right swapped), as a new database"
    description = ("Mirror clips (by name, --all, or --select) on their own skeletons and write them as a new "
                   "database: each original, then its mirror image NAME.mirror (positions the world reflection of "
                   "the partner joints', for any rest pose; labels' left and right swapped; a mirror_of label; the "
                   "table's columns such as cost and flags kept). Joints pair by name (Left/Right, L/R, l_/r_). "
                   "Export, train on or splice the output as any database.")

    def add_arguments(self, s) -> None:
        add_clip_arguments(s, "mirror")
        s.add_argument("-o", "--output", required=True, help="database to write (.h5)")
        s.add_argument("--originals", action=argparse.BooleanOptionalAction,
                       default=DEFAULT_ORIGINALS,
                       help="write each original before its mirror image (default: on; --no-originals: mirrors only)")
        add_output_flags(s, quiet_help="no progress bar or summary")

    def run(self, args) -> int:
        from ..retarget.mirror import mirror_clips

        clips = chosen_clips(args, "mirror")
        output(args, "database")
        report = mirror_clips(args.database, clips, out=args.output, select=args.select,
                              originals=args.originals, overwrite=args.force, command=command_line(args),
                              progress=lambda it, total, desc: progress(it, total, desc, args.quiet, unit="chunk"))
        say(args, f"wrote {report.summary()}")
        return 0


register_command(Mirror())
