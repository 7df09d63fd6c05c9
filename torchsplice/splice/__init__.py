"""Splicing methods: the Heck-Kovar-Gleicher splice and the naive and CPMC baselines."""

from .api import METHODS, NotLocomotingError, SpliceOptions, SpliceResult, splice, splice_pairs
from .heck import AlignOptions

__all__ = ["METHODS", "AlignOptions", "SpliceOptions", "SpliceResult", "NotLocomotingError", "splice", "splice_pairs"]
