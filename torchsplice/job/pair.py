"""One pair of a database's clips, spliced as the job splices it: :func:`splice_pair`.

What the ``splice`` command does, from Python: the two clips are read by name; an action on
another skeleton is retargeted onto the locomotion's first, as :func:`~torchsplice.job.splice_all`
does (:func:`~torchsplice.retarget.clips.onto_skeleton`); a method that needs a
plain-locomotion reference (``cpmc``) gets the one the spec's ``[clips.reference]`` rule finds
unless one is named; and a pair whose gaits match poorly gets the job's ``poor alignment``
words in its result's ``notes``::

    from torchsplice.job import splice_pair
    from torchsplice.formats.bvh import write_bvh
    result = splice_pair("sample.h5", locomotion="walk_01", action="wave_02")
    write_bvh(result.motion, "walk_wave.bvh")

:func:`torchsplice.splice.splice` is the same on two :class:`~torchsplice.core.motion.Motion`
of one skeleton, with no database around them.
"""

from __future__ import annotations

import dataclasses

from ..core.errors import TorchspliceError
from ..retarget.clips import onto_skeleton
from ..splice import SpliceOptions, SpliceResult, splice
from ..splice.defaults import DEFAULT_METHOD
from ..splice.references import find_reference
from ..splice.registry import Method, get_method
from ..store.database import MotionDatabase
from .plan import leg_length
from .task import poor_alignment

__all__ = ["splice_pair"]

POOR_ALIGNMENT_ADVICE = ("the two gaits match worse than 95% of walk-onto-walk pairs (whose median is 0.05); check "
                         "the result, or cut long takes into windows on import")
"""What a poorly aligned pair's note adds to the flag's words."""


def splice_pair(database, locomotion: str, action: str, method: str | Method = DEFAULT_METHOD,
                reference: str | None = None, options: SpliceOptions | None = None) -> SpliceResult:
    """Splice the clip ``action`` of ``database`` (a path) onto its clip ``locomotion``.

    ``reference`` names the plain-locomotion reference for a method that needs one (``cpmc``;
    default: the spec's ``[clips.reference]`` rule); other methods refuse one. The result is on
    the locomotion's skeleton (an action on another one is retargeted onto it first) and its
    ``notes`` say what a person should check: a clip forced although it does not locomote, a
    standing action, a poor alignment. Raises :class:`~torchsplice.core.errors.TorchspliceError`
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
    return result
