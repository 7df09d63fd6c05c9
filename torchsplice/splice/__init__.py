"""Splicing methods: the Heck-Kovar-Gleicher splice and the naive and CPMC baselines, for
actions that locomote (time-aligned) and for standing actions (looped, held or fitted)."""

from .api import (METHODS, TIMINGS, NotLocomotingError, SpliceOptions, SpliceResult, splice, splice_pairs,
                  splice_standing)
from .heck import AlignOptions

__all__ = ["METHODS", "TIMINGS", "AlignOptions", "SpliceOptions", "SpliceResult", "NotLocomotingError", "splice",
           "splice_pairs", "splice_standing"]
