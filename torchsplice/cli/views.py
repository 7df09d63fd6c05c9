"""Commands that show clips: ``render`` (stick figures as GIF, MP4 or a PNG filmstrip) and
``view`` (one self-contained HTML page playing them in 3D)."""

from __future__ import annotations

import sys

from .base import Command, register_command
from .common import add_output_flags, bounded_int, expand_clips, locked, output, positive_float, positive_int, say
from ..viz.defaults import (CAMERAS, DEFAULT_AZIMUTH, DEFAULT_CAMERA, DEFAULT_ELEVATION, DEFAULT_FRAMES, DEFAULT_MAX_CLIPS,
                           DEFAULT_MAX_SECONDS, MAX_FILMSTRIP)


class Render(Command):
    name = "render"
    help = "stick-figure preview of clips side by side (GIF, MP4 or PNG filmstrip)"
    description = ("Draw clips as stick figures side by side (e.g. locomotion, action, naive, spliced) from a camera "
                   "that follows each root and turns with its heading, with clip names as titles and a ground grid; "
                   "--overlay adds a panel drawing clips over each other (a splice with its naive result in grey). "
                   ".gif and .mp4 (needs ffmpeg) animate; .png is a filmstrip.")

    def add_arguments(self, s) -> None:
        frames = DEFAULT_FRAMES
        s.add_argument("database", help="motion database (.h5)")
        s.add_argument("clips", nargs="+", metavar="CLIP",
                       help="clip names, or selectors ('walk_curve+*', 'method:naive'): their clips in row order")
        s.add_argument("-o", "--output", required=True, help="file to write (.gif, .mp4, .png)")
        s.add_argument("--frames", type=bounded_int(1, MAX_FILMSTRIP), default=frames, metavar="N",
                       help=f"frames per clip in a PNG filmstrip (default {frames}, at most {MAX_FILMSTRIP})")
        s.add_argument("--max-seconds", type=positive_float, default=DEFAULT_MAX_SECONDS,
                       metavar="SECONDS", help="show at most this many seconds")
        s.add_argument("--overlay", nargs="+", metavar="CLIP",
                       help="one more panel: these clips drawn over each other, the first in colour, the others in "
                            "grey at the same times, seen from the first's camera (e.g. 'walk_curve+carry_box' "
                            "'walk_curve+carry_box.naive')")
        camera = DEFAULT_CAMERA
        s.add_argument("--camera", choices=CAMERAS, default=camera,
                       help=f"heading: the camera turns with each character's heading; world: its direction is "
                            f"fixed (default {camera}); it follows the character in both")
        azimuth, elevation = DEFAULT_AZIMUTH, DEFAULT_ELEVATION
        s.add_argument("--azimuth", type=float, default=azimuth, metavar="DEG",
                       help=f"the camera's angle about the up axis at the first frame (default {azimuth:g}: front "
                            "right of a character facing +Z; -90 its right side)")
        s.add_argument("--elevation", type=float, default=elevation, metavar="DEG",
                       help=f"the camera's height above the floor, in degrees (default {elevation:g})")
        s.add_argument("--sources", nargs="+", metavar="DB",
                       help="databases holding clips not in DATABASE, e.g. a spliced clip's locomotion and action "
                            "(default: the inputs its run record names)")
        add_output_flags(s)

    def run(self, args) -> int:
        from ..viz.render import render
        from ..viz.sources import read_clips

        out = output(args, "render")
        clips, spec = read_clips(args.database, expand_clips(args.database, args.clips), sources=args.sources)
        panels, titles = list(clips), [c.name for c in clips]
        if args.overlay:
            over, _ = read_clips(args.database, expand_clips(args.database, args.overlay), sources=args.sources)
            panels.append(over)
            titles.append(over[0].name + (f"; grey: {', '.join(c.name for c in over[1:])}" if len(over) > 1 else ""))
        longest = max(p[0].num_frames if isinstance(p, list) else p.num_frames for p in panels)  # an overlay's too
        frames = args.frames
        if out.suffix.lower() == ".png" and frames > longest:
            print(f"note: --frames {frames} is more than the {longest} frames of the longest clip; drawing {longest}",
                  file=sys.stderr)
            frames = longest
        with locked(out, args):
            render(panels, out, titles=titles, up_axis=spec.up_axis, frames=frames, max_seconds=args.max_seconds,
                   camera=args.camera, azimuth=args.azimuth, elevation=args.elevation)
        overlay = f" and a panel of {len(panels[-1])} drawn over each other" if args.overlay else ""
        say(args, f"wrote {out}: {len(clips)} clip{'s' if len(clips) != 1 else ''}{overlay}")
        return 0


class View(Command):
    name = "view"
    help = "one self-contained HTML page that plays clips in 3D in a browser"
    description = ("Write an HTML file (no server, no network: three.js is inlined) that plays the database's clips "
                   "side by side in 3D, with an orbit camera, a timeline and a picker filtered by role, method and "
                   "label; a spliced clip shows with its locomotion, its action and the other methods' results in one "
                   "click.")

    def add_arguments(self, s) -> None:
        max_clips = DEFAULT_MAX_CLIPS
        s.add_argument("database", help="motion database (.h5)")
        s.add_argument("clips", nargs="*", metavar="CLIP",
                       help="clips to include (with the sources and other methods of spliced ones), names or "
                            "selectors ('role:spliced', 'action:wave'); default: all, up to --max-clips")
        s.add_argument("-o", "--output", required=True, help="page to write (.html)")
        s.add_argument("--sources", nargs="+", metavar="DB",
                       help="databases holding the spliced clips' locomotions and actions (default: as recorded)")
        s.add_argument("--max-clips", type=positive_int, default=max_clips, metavar="N",
                       help=f"at most this many clips when none are named (default {max_clips}, about 8 MB for 10 s "
                            "clips)")
        add_output_flags(s)

    def run(self, args) -> int:
        from ..viz.viewer import viewer_notes, write_viewer
        from .common import flag

        out = output(args, "viewer")
        with locked(out, args):
            got = write_viewer(args.database, out, clips=expand_clips(args.database, args.clips) if args.clips else args.clips,
                               sources=args.sources, max_clips=args.max_clips,
                               quiet=True)
        if not args.quiet:
            for line in viewer_notes(got, args.database, args.max_clips, flag):
                print(line, file=sys.stderr)
        say(args, f"wrote {out}: {len(got.names)} clip{'s' if len(got.names) != 1 else ''}, {got.size / 1e6:.1f} MB")
        return 0


register_command(Render())
register_command(View())
