"""Judging results: errors against captured ground truth (and, later, quality metrics)."""

from .ground_truth import GroundTruthTriple, bandai_namco_triples, upper_body_error

__all__ = ["GroundTruthTriple", "bandai_namco_triples", "upper_body_error"]
