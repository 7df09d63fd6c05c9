"""Judging results: metrics with known answers, error against captured ground truth, reports.

The names below are imported on first use, so that the report's defaults (:mod:`.defaults`)
are read without torch.
"""

from typing import TYPE_CHECKING

from ..core.lazy import lazy_names

if TYPE_CHECKING:  # pragma: no cover
    from .ground_truth import GroundTruthTriple, bandai_namco_triples, upper_body_error
    from .metrics import arm_leg_phase, foot_skate, gait_period, phase_range, posture_kept, posture_offset

__all__ = ["GroundTruthTriple", "bandai_namco_triples", "upper_body_error", "foot_skate", "arm_leg_phase",
           "gait_period", "phase_range", "posture_offset", "posture_kept"]

__getattr__, __dir__ = lazy_names(__name__, {
    **dict.fromkeys(("GroundTruthTriple", "bandai_namco_triples", "upper_body_error"), ".ground_truth"),
    **dict.fromkeys(("arm_leg_phase", "foot_skate", "gait_period", "phase_range", "posture_kept", "posture_offset"),
                    ".metrics"),
})
