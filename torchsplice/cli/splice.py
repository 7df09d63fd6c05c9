"""Commands on one pair of clips: ``splice`` (write the result as BVH) and ``plot-alignment``
(draw the pair's time alignment); and the splice's flags, which ``splice-all`` shares.

The splice's flags take their defaults from the splice's declared defaults
(:mod:`torchsplice.splice.defaults`), which ``SpliceOptions`` and ``AlignOptions`` (the commands
on one pair) and ``JobConfig`` (``splice-all``) all take (:func:`add_splice_options`).
"""

from __future__ import annotations

import sys

from .base import Command, register_command
from .common import add_output_flags, device, locked, output, positive_int, say, share
from ..core.errors import TorchspliceError
from ..job.defaults import DEFAULT_KEEP_HANDS_OUT
from ..splice.defaults import (DEFAULT_ACTING_LIMBS, DEFAULT_BACKEND, DEFAULT_DEVICE, DEFAULT_FORCE, DEFAULT_MAX_RUN,
                               DEFAULT_METHOD, DEFAULT_POSTURE, DEFAULT_TIMING, DEFAULT_TWIST, LIMBS, TIMINGS)

ACTING_LIMBS_AUTO = "auto"
"""How ``--acting-limbs`` spells the library's ``acting_limbs=None`` (found per clip);
``torchsplice.splice.standing.parse_limbs`` reads it."""


def methods() -> tuple[str, ...]:
    """The registered methods, for --help and --method (the registry loads no torch)."""
    from ..splice.registry import available_methods

    return available_methods()


def backend_choices() -> tuple[str, ...]:
    """``--backend``'s choices: ``auto`` and the registered backends (plug-ins included)."""
    from ..splice.backends import backend_choices as choices

    return choices()


def splice_defaults() -> dict:
    """The splice's defaults as flags see them (:mod:`torchsplice.splice.defaults`: those of
    ``SpliceOptions`` and ``AlignOptions``, for one pair, and of ``JobConfig``, for splice-all)."""
    limbs = DEFAULT_ACTING_LIMBS
    return {"max_run": DEFAULT_MAX_RUN, "no_posture": not DEFAULT_POSTURE, "twist": DEFAULT_TWIST,
            "timing": DEFAULT_TIMING, "force_locomotion": DEFAULT_FORCE, "device": DEFAULT_DEVICE,
            "backend": DEFAULT_BACKEND, "acting_limbs": ACTING_LIMBS_AUTO if limbs is None else ",".join(limbs)}


def add_pair_args(s) -> None:
    s.add_argument("database", help="motion database (.h5)")
    s.add_argument("--locomotion", required=True, metavar="NAME", help="clip giving root and lower body")
    s.add_argument("--action", required=True, metavar="NAME", help="clip giving the upper body")


def add_splice_options(s, standing: bool = True) -> None:
    """The splice's flags, with the splice's defaults (:func:`splice_defaults`); ``standing=False``
    leaves out those about clips that do not locomote (plot-alignment always time-aligns)."""
    d = splice_defaults()
    s.add_argument("--max-run", type=positive_int, default=d["max_run"], metavar="L",
                   help=f"slope limit of the timewarp: at most L frames of one clip while the other waits "
                        f"(default {d['max_run']})")
    s.add_argument("--no-posture", action="store_true", default=d["no_posture"],
                   help="skip posture transfer (splice method)")
    s.add_argument("--twist", type=share, default=d["twist"], metavar="SHARE",
                   help="share (0 to 1) of the locomotion's torso twist that posture transfer adds, e.g. 0.5 on side "
                        f"steps (splice method; default {d['twist']:g}: the action's posture as it is)")
    if not standing:
        s.set_defaults(force_locomotion=True, timing=d["timing"], acting_limbs=d["acting_limbs"])
    else:
        _add_standing_options(s, d)
    s.add_argument("--device", default=d["device"],
                   help="where the work runs: cpu (default: the compiled splicer) or a torch device such as cuda")
    s.add_argument("--backend", default=d["backend"], choices=list(backend_choices()),
                   help="what computes the splices: auto (default: the compiled splicer on the CPU, torch on CUDA), "
                        "compiled, torch, or a backend a --plugin module registers")


def _add_standing_options(s, d: dict) -> None:
    limbs = LIMBS
    s.add_argument("--force-locomotion", action="store_true", default=d["force_locomotion"],
                   help="time-align clips that do not locomote (the method's limit) instead of refusing a locomotion "
                        "that does not locomote and splicing a standing action by --timing")
    s.add_argument("--timing", choices=TIMINGS, default=d["timing"],
                   help="how an action that does not locomote (a standing action: a wave, a bow) fills the locomotion: "
                        "loop: play it from its start and loop it (the loop holds the whole gesture) with a seamless "
                        "blend (default); hold: play it once and hold its last frame; fit: time-scale the whole action "
                        "to the locomotion's length (faster onto a shorter one). Onto a locomotion shorter than the "
                        "action, loop and hold play the window of the action where the acting arms move most")
    s.add_argument("--acting-limbs", default=d["acting_limbs"], metavar="LIMBS",
                   help=f"the arms standing actions act with: {ACTING_LIMBS_AUTO} (default: found from each clip's "
                        f"data), none, or {', '.join(limbs)} or both; the other arm keeps the locomotion's swing "
                        "(splice method)")


def splice_options(args):
    """The ``SpliceOptions`` of the flags."""
    from ..splice import AlignOptions, SpliceOptions

    return SpliceOptions(align=AlignOptions(max_run=args.max_run), posture=not args.no_posture,
                         force=args.force_locomotion, device=device(args.device), timing=args.timing,
                         acting_limbs=_acting_limbs(args), twist=args.twist, backend=args.backend)


def _acting_limbs(args):
    from ..splice.standing import parse_limbs

    try:
        return parse_limbs(args.acting_limbs)
    except ValueError as exc:
        raise TorchspliceError(f"--acting-limbs: {exc}") from None


def _read_pair(db, args):
    """The ``--locomotion`` and ``--action`` clips of an open database, and the spec that fits them."""
    loco, act = db.read(args.locomotion), db.read(args.action)
    return loco, act, db.spec(db.clip_info(args.locomotion)["skeleton"])


class Splice(Command):
    name = "splice"
    help = "splice one action onto one locomotion and write a BVH file"
    description = ("Splice the upper body of an action clip onto the lower body of a locomotion clip of the same "
                   "database (clip names as `info` lists them); an action on another skeleton is retargeted onto the "
                   "locomotion's first, as splice-all does. Methods: splice (Heck, Kovar & Gleicher 2006: "
                   "timewarp, spatial alignment, posture transfer), naive (per-bone upper-body replacement, no "
                   "timewarp) and cpmc (differencing against a plain-locomotion reference of the action's performer, "
                   "chosen by the spec's [clips.reference] rule or named with --reference).")

    def add_arguments(self, s) -> None:
        method = DEFAULT_METHOD
        add_pair_args(s)
        s.add_argument("-o", "--output", required=True, help="BVH file to write")
        s.add_argument("--method", default=method, choices=methods(),
                       help=f"splicing method (default {method}; plug-ins add more, see --plugin)")
        s.add_argument("--reference", metavar="NAME", help="plain-locomotion reference of the action (cpmc)")
        add_splice_options(s)
        s.add_argument("--no-keep-hands-out", dest="keep_hands_out", action="store_false", default=DEFAULT_KEEP_HANDS_OUT,
                       help="write the splice as it comes, even where it puts a hand or forearm inside the body deeper "
                            "than its sources do (by default the arm is moved out, as splice-all does, and a note "
                            "says on how many frames)")
        add_output_flags(s)

    def run(self, args) -> int:
        from ..formats.bvh import write_bvh
        from ..job.pair import splice_pair
        from ..splice.registry import get_method

        method = get_method(args.method)
        out = output(args, "bvh")
        result = splice_pair(args.database, args.locomotion, args.action, method=method, reference=args.reference,
                             options=splice_options(args), keep_hands_out=args.keep_hands_out)
        with locked(out, args):
            write_bvh(result.motion, out)
        extra = f", reference {result.reference}" if result.reference else ""
        if result.timing != "timewarp":
            acting = f"; acting limbs: {', '.join(result.acting) or 'none'}" if method.uses_acting_limbs else ""
            detail = f"; standing action ({result.timing}{acting})"
        else:
            shown = [f"alignment cost {result.cost:.3g}" if "cost" in method.diagnostics else "",
                     f"action cropped by {result.crop} frames" if "crop" in method.diagnostics else "",
                     f"posture rotation {result.posture_deg:.1f} deg" if "posture" in method.diagnostics else ""]
            detail = "".join(f"{'; ' if not k else ', '}{t}" for k, t in enumerate(t for t in shown if t))
        say(args, f"wrote {out}: {method.name} of {result.action} onto {result.locomotion}{extra}: "
                  f"{result.motion.num_frames} frames at {result.motion.fps:g} fps{detail}")
        for note in result.notes:
            print(f"note: {note}", file=sys.stderr)
        return 0


class PlotAlignment(Command):
    name = "plot-alignment"
    help = "picture of one pair's time alignment (distance grid, DP path, curve)"
    description = ("Draw the lower-body distance grid of a locomotion and an action as a heat map with the optimal "
                   "DP path and the fitted alignment curve over it (Heck et al. 2006, Figure 3), and the per-frame "
                   "pelvis correction angle below. PNG, PDF or SVG. Clips that do not locomote are time-aligned "
                   "anyway, as splice --force-locomotion does (without it, splice fills the locomotion with a "
                   "standing action by --timing).")

    def add_arguments(self, s) -> None:
        add_pair_args(s)
        s.add_argument("-o", "--output", required=True, help="picture to write (.png, .pdf, .svg)")
        add_splice_options(s, standing=False)
        add_output_flags(s)

    def run(self, args) -> int:
        from ..retarget.clips import onto_skeleton
        from ..store.database import MotionDatabase
        from ..viz.alignment import plot_alignment

        out = output(args, "plot")
        with MotionDatabase.open(args.database) as db:
            loco, act, spec = _read_pair(db, args)
            act = (onto_skeleton(db, args.database, [act], db.clip_info(loco.name)["skeleton"]) or [act])[0]
        with locked(out, args):
            plot_alignment(loco, act, spec, out, options=splice_options(args))
        say(args, f"wrote {out}: alignment of {act.name} to {loco.name}")
        return 0


register_command(Splice())
register_command(PlotAlignment())
