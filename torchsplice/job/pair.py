"""One pair of a database's clips, spliced as the job splices it: :func:`splice_pair`.

What the ``splice`` command does, from Python: the two clips are read by name; an action on
another skeleton is retargeted onto the locomotion's first, as :func:`~torchsplice.job.splice_all`
does (:func:`~torchsplice.retarget.clips.onto_skeleton`); a method that needs a
plain-locomotion reference (``cpmc``) gets the one the spec's ``[clips.reference]`` rule finds
unless one is named; a result that puts a hand inside the body deeper than its sources do has
its arm moved out as the job does (``keep_hands_out``, on by default; a note says so); and a
pair whose gaits match poorly gets the job's ``poor alignment`` words in its result's ``notes``::

    from torchsplice.job import splice_pair
    from torchsplice.formats.bvh import write_bvh
    result = splice_pair("sample.h5", locomotion="walk_01", action="wave_02")
    write_bvh(result.motion, "walk_wave.bvh")

:func:`torchsplice.splice.splice` is the same on two :class:`~torchsplice.core.motion.Motion`
of one skeleton, with no database around them.
"""

from __future__ import annotations

import dataclasses

import torch

from ..core.errors import TorchspliceError
from ..ops.body import body_of
from ..ops.hands import arms_of, keep_hands_out
from ..ops.plausibility import penetration_packed
from ..retarget.clips import onto_skeleton
from ..splice import SpliceOptions, SpliceResult, splice
from ..splice.defaults import DEFAULT_METHOD
from ..splice.references import find_reference
from ..splice.registry import Method, get_method
from ..store.database import MotionDatabase
from .defaults import DEFAULT_KEEP_HANDS_OUT
from .plan import leg_length
from .task import allowed_inside, poor_alignment

__all__ = ["splice_pair", "hands_kept_out"]

POOR_ALIGNMENT_ADVICE = ("the two gaits match worse than 95% of walk-onto-walk pairs (whose median is 0.05); check "
                         "the result, or cut long takes into windows on import")
"""What a poorly aligned pair's note adds to the flag's words."""


def splice_pair(database, locomotion: str, action: str, method: str | Method = DEFAULT_METHOD,
                reference: str | None = None, options: SpliceOptions | None = None,
                keep_hands_out: bool = DEFAULT_KEEP_HANDS_OUT) -> SpliceResult:
    """Splice the clip ``action`` of ``database`` (a path) onto its clip ``locomotion``.

    ``reference`` names the plain-locomotion reference for a method that needs one (``cpmc``;
    default: the spec's ``[clips.reference]`` rule); other methods refuse one. The result is on
    the locomotion's skeleton (an action on another one is retargeted onto it first) and its
    ``notes`` say what a person should check: a clip forced although it does not locomote, a
    standing action, a poor alignment, arms moved out of the body (``keep_hands_out``: as
    :func:`~torchsplice.job.splice_all` does, :func:`hands_kept_out`). Raises :class:`~torchsplice.core.errors.TorchspliceError`
    in one line naming the clip or option.
    """
    meth = get_method(method)
    if reference is not None and not meth.needs_reference:
        raise TorchspliceError(f"{{reference}} is only used by methods that need a reference clip (cpmc), not {meth.name}",
                               options=("reference",))
    with MotionDatabase.open(database) as db:
        loco, act = db.read(locomotion), db.read(action)
        spec = db.spec(db.clip_info(locomotion)["skeleton"])
        ref = None
        if meth.needs_reference:
            name = reference
            if name is None:
                name = find_reference(act.name, act.labels, db.clip_table().captures(),
                                      db.spec(db.clip_info(action)["skeleton"]))
            ref = db.read(name) if name is not None else None  # a standing action needs none
        moved = onto_skeleton(db, database, [act] + ([ref] if ref is not None else []),
                              db.clip_info(locomotion)["skeleton"])
        if moved is not None:  # the action on another skeleton: retargeted onto the locomotion's first
            act, ref = moved[0], (moved[1] if ref is not None else None)
    try:
        result = splice(loco, act, spec, method=meth, reference=ref, options=options)
    except TorchspliceError as exc:
        if meth.needs_reference and ref is None and "reference" in str(exc):
            raise TorchspliceError(f"no plain-locomotion reference found for action {act.name!r}: name one with "
                                   "{reference} (or add a [clips.reference] rule to the spec)",
                                   options=("reference",)) from None
        raise
    if "cost" in meth.diagnostics:
        poor = poor_alignment(result.cost, leg_length(loco.skeleton, spec.bind(loco.skeleton)))
        if poor:
            result = dataclasses.replace(result, notes=result.notes + (f"{poor}: {POOR_ALIGNMENT_ADVICE}",))
    return hands_kept_out(result, loco, act, spec) if keep_hands_out else result


def hands_kept_out(result: SpliceResult, locomotion, action, spec) -> SpliceResult:
    """``result`` with its arms moved out of the body where a hand or forearm goes deeper inside
    it than ``locomotion``'s and ``action``'s do (the job's rule,
    :func:`~torchsplice.job.task.allowed_inside`; :func:`torchsplice.ops.hands.keep_hands_out`),
    with a note saying how many frames changed; ``result`` itself where nothing is to move."""
    motion = result.motion
    skeleton = motion.skeleton
    roles = spec.bind(skeleton)
    body = body_of(skeleton, roles)

    def inside(m) -> tuple[float, float]:  # (share of frames, deepest, the skeleton's units)
        share, depth = penetration_packed(m.global_positions().to(torch.float64), [m.num_frames], body)
        return float(share[0]), float(depth[0])

    (share, depth), (share_l, depth_l), (share_a, depth_a) = inside(motion), inside(locomotion), inside(action)
    allowed = float(allowed_inside(share, share_l, share_a, depth_l, depth_a))
    if not (share > 0 and depth > allowed):
        return result
    rot, corrected = keep_hands_out(motion.rotations, motion.local_translations(), [motion.num_frames], motion.fps,
                                    skeleton, body, arms_of(skeleton, roles, body), allowed)
    note = (f"a hand or forearm was inside the body on {100 * share:.0f}% of the frames (the locomotion's "
            f"{100 * share_l:.0f}%, the action's {100 * share_a:.0f}%): the arm was moved out on "
            f"{int(corrected[0])} frames (keep_hands_out=False, --no-keep-hands-out, keeps the splice as it came)")
    return dataclasses.replace(result, motion=dataclasses.replace(motion, rotations=rot), notes=result.notes + (note,))
