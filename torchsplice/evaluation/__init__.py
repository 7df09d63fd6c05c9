"""Judging results: metrics with known answers, error against captured ground truth, reports."""

from .ground_truth import GroundTruthTriple, bandai_namco_triples, upper_body_error
from .metrics import arm_leg_phase, foot_skate, gait_period, phase_range, posture_kept, posture_offset

__all__ = ["GroundTruthTriple", "bandai_namco_triples", "upper_body_error", "foot_skate", "arm_leg_phase",
           "gait_period", "phase_range", "posture_offset", "posture_kept"]
