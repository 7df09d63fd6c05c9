"""The splice's option defaults and allowed values, declared once: :class:`~.options.SpliceOptions`,
:class:`~.options.AlignOptions`, :func:`~.api.splice` and :mod:`.standing` take them from here, and
so do the job's configuration (:mod:`torchsplice.job.defaults`) and the command line.

Every package whose options the command line shows has such a module, ``<package>/defaults.py``
(:mod:`torchsplice.job.defaults`, :mod:`torchsplice.formats.defaults`, ...): allowed values are
plural nouns (``TIMINGS``), defaults ``DEFAULT_<OPTION>``. A ``defaults`` module imports only
the standard library and other ``defaults`` modules, so that ``torchsplice --help`` reads them
without loading torch, numpy or h5py (tests/project/test_defaults.py).
"""

from __future__ import annotations

__all__ = ["TIMINGS", "LIMBS", "DEFAULT_METHOD", "DEFAULT_MAX_RUN", "DEFAULT_POSTURE", "DEFAULT_TWIST", "DEFAULT_FORCE",
           "DEFAULT_DEVICE", "DEFAULT_BACKEND", "DEFAULT_TIMING", "DEFAULT_ACTING_LIMBS"]

TIMINGS = ("loop", "hold", "fit")
"""How a standing action fills a longer (or shorter) locomotion."""
LIMBS = ("left_arm", "right_arm")
"""Limbs an action may act with (the legs always come from the locomotion)."""

DEFAULT_METHOD = "splice"
"""The splicing method of :func:`~.api.splice` (and the job's only one, by default)."""
DEFAULT_MAX_RUN = 3
"""The timewarp's slope limit (``AlignOptions.max_run``)."""
DEFAULT_POSTURE = True
"""Posture transfer on (``SpliceOptions.posture``)."""
DEFAULT_TWIST = 0.0
"""The share of the locomotion's torso twist that posture transfer adds (``SpliceOptions.twist``)."""
DEFAULT_FORCE = False
"""Refuse clips that do not locomote (``SpliceOptions.force``, the job's ``force_locomotion``)."""
DEFAULT_DEVICE: str | None = None
"""Where the tensor work runs (``None``: the CPU)."""
DEFAULT_BACKEND = "auto"
"""What computes the splices (``auto``: the compiled splicer on the CPU, torch on other devices)."""
DEFAULT_TIMING = "loop"
"""How a standing action fills the locomotion (one of :data:`TIMINGS`)."""
DEFAULT_ACTING_LIMBS: tuple[str, ...] | None = None
"""The arms standing actions act with (``None``: found per clip from the data)."""
