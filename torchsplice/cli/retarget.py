"""``retarget``: clips of a database played on another skeleton, written as a new database.

The command parses its flags and calls :func:`torchsplice.retarget.retarget_clips`, which does
the rest exactly as from Python.
"""

from __future__ import annotations

import argparse

from .base import Command, register_command
from .common import add_clip_arguments, add_output_flags, chosen_clips, command_line, output, progress, say
from ..retarget.defaults import DEFAULT_FIX_FEET


class Retarget(Command):
    name = "retarget"
    help = "play clips of a database on another skeleton (another dataset's, a BVH rig's, or SMPL's)"
    description = ("Retarget clips (by name, --all, or --select) onto TARGET and write them as a new database: rest "
                   "poses aligned bone by bone whatever each rig's rest pose, the trajectory scaled by leg length, "
                   "and the feet held where the source's stand (--no-fix-feet to leave them). TARGET is a database "
                   "(other.h5, or other.h5:K for its skeleton K as `info` lists them), a BVH file, or the built-in "
                   "SMPL body (smpl22). Results keep their names and labels and gain retargeted_from and "
                   "retargeted_to labels.")

    def add_arguments(self, s) -> None:
        add_clip_arguments(s, "retarget")
        s.add_argument("--to", required=True, metavar="TARGET",
                       help="other.h5, other.h5:K, a .bvh file, or smpl22")
        s.add_argument("-o", "--output", required=True, help="database to write (.h5)")
        s.add_argument("--fix-feet", action=argparse.BooleanOptionalAction,
                       default=DEFAULT_FIX_FEET,
                       help="hold each foot where the source's stands, at the source's height above the floor "
                            "(default: on)")
        add_output_flags(s, quiet_help="no progress bar or summary")

    def run(self, args) -> int:
        from ..retarget import retarget_clips

        clips = chosen_clips(args, "retarget")
        output(args, "database")
        report = retarget_clips(args.database, clips, to=args.to, out=args.output, select=args.select,
                                fix_feet=args.fix_feet, overwrite=args.force, command=command_line(args),
                                progress=lambda it, total, desc: progress(it, total, desc, args.quiet, unit="chunk"))
        say(args, f"wrote {report.summary()}")
        for source, notes in report.maps.items():
            parts = [f"{what} {', '.join(names)}" for what, names in (("held at rest:", notes["held"]),
                                                                       ("folded into their parents:", notes["folded"]))
                     if names]
            if parts:
                say(args, f"  from {source}: " + "; ".join(parts))
        return 0


register_command(Retarget())
