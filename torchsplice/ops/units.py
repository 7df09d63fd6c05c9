"""Length units: convert clips, skeletons and specs from one unit to another.

Datasets come in different units: Bandai Namco, LAFAN1 and the sample in centimetres, CMU's
cgspeed BVH in its own unit (``"cmu"``: the ASF ``length 0.45``, 1 unit = 1/0.45 inch, so
1 unit = 5.644 cm). Converting every clip to one unit lets datasets share a database
(``torchsplice import ... --units cm``) with one ``units`` attribute, not ``mixed``.

The table of units is :data:`torchsplice.specs.UNITS` (metres per unit): ``m``, ``cm``,
``mm``, ``in`` (inches), ``ft`` (feet) and ``cmu``. A conversion multiplies every length by
:func:`unit_factor`: the skeleton's rest offsets and End Site offsets, the root translation
and the animated joint translations. Rotations have no length and stay as they are, so the
world positions by forward kinematics scale by exactly the same factor.
"""

from __future__ import annotations

from dataclasses import replace

from ..core.errors import TorchspliceError
from ..core.motion import Motion
from ..core.skeleton import Skeleton
from ..specs import UNITS, DatasetSpec

__all__ = ["UNITS", "CONVERTIBLE_UNITS", "HUMAN_SIZE_M", "unit_factor", "centimetres", "scale_skeleton", "scale_motion", "convert_units",
           "implausible_size"]

CONVERTIBLE_UNITS = tuple(u for u, f in UNITS.items() if f is not None)
"""The units a clip can be converted to or from (every unit of :data:`UNITS` but ``unknown``)."""


HUMAN_SIZE_M = (0.4, 4.0)
"""The range of a human skeleton's :meth:`~torchsplice.core.skeleton.Skeleton.size` (its longest
path between two leaves: about the height or the arm span), in metres, wide enough for a child
and a long-tailed costume; a file in other units than its spec says lies a factor 10 or more
outside it."""


def implausible_size(skeleton: Skeleton, units: str) -> str | None:
    """Why ``skeleton`` cannot be a human in ``units`` (its size far outside
    :data:`HUMAN_SIZE_M`), or ``None`` (also for unknown units)."""
    per = UNITS.get(units)
    size = skeleton.size()
    if per is None or size <= 0:
        return None
    metres = size * per
    lo, hi = HUMAN_SIZE_M
    if lo <= metres <= hi:
        return None
    return (f"the skeleton measures {size:.3g} {units} across ({metres:.3g} m), not a human's size: are the file's units "
            f"{units}? (a spec that states its units, or converting them at import, sets them right)")


def centimetres(units: str) -> float:
    """Centimetres in one unit of ``units`` (a spec's), NaN where they are unknown: what
    figures stated in centimetres are converted by."""
    f = UNITS.get(units)
    return float("nan") if f is None else f * 100.0


def unit_factor(source: str, target: str, where: str = "") -> float:
    """How many ``target`` units make one ``source`` unit (``unit_factor("in", "cm") == 2.54``).

    ``where`` (a spec or file) prefixes the one-line :class:`TorchspliceError` raised for an
    unknown unit, or for ``"unknown"`` units, which cannot be converted.
    """
    at = f"{where}: " if where else ""
    for u in (source, target):
        if u not in UNITS:
            raise TorchspliceError(f"{at}unknown length unit {u!r} (known: {', '.join(CONVERTIBLE_UNITS)})")
    if UNITS[source] is None:
        raise TorchspliceError(f"{at}the units are unknown, so they cannot be converted to {target!r}; "
                               "declare them in the dataset spec ([dataset] units, see datasets_spec/README.md)")
    if UNITS[target] is None:
        raise TorchspliceError(f"{at}cannot convert to unknown units; name a unit ({', '.join(CONVERTIBLE_UNITS)})")
    if source == target:
        return 1.0
    return UNITS[source] / UNITS[target]


def scale_skeleton(skeleton: Skeleton, factor: float) -> Skeleton:
    """``skeleton`` with its rest offsets ``(J, 3)`` and End Site offsets ``(E, 3)`` times ``factor``
    (names, parents and channels unchanged)."""
    return Skeleton(skeleton.names, skeleton.parents, skeleton.offsets * factor, skeleton.channels,
                    skeleton.end_site_parents, skeleton.end_site_offsets * factor)


def scale_motion(motion: Motion, factor: float, skeleton: Skeleton | None = None) -> Motion:
    """``motion`` with every length times ``factor``: root translation ``(T, 3)``, animated joint
    translations ``(T, J, 3)`` and the skeleton (:func:`scale_skeleton`, or ``skeleton`` if given,
    e.g. one already scaled for the clips of a file). Rotations are kept (no copy)."""
    sk = scale_skeleton(motion.skeleton, factor) if skeleton is None else skeleton
    return replace(motion, skeleton=sk, root_translation=motion.root_translation * factor,
                   translations=None if motion.translations is None else motion.translations * factor,
                   labels=dict(motion.labels))


def convert_units(motion: Motion, spec: DatasetSpec, target: str) -> tuple[Motion, DatasetSpec]:
    """``motion`` converted from its spec's declared units to ``target``, and the spec saying so.

    Returns ``(clip, spec)``: the clip with every length scaled (:func:`scale_motion`) and a copy
    of ``spec`` whose ``units`` is ``target`` (joint roles and clip rules unchanged), which is
    the one to store with the clip. A spec whose units are already ``target`` returns both
    unchanged. Unknown units give a one-line :class:`TorchspliceError` naming the spec.
    """
    factor = unit_factor(spec.units, target, spec.where)
    if spec.units == target:
        return motion, spec
    return scale_motion(motion, factor), replace(spec, units=target)
