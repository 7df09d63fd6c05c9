"""The database job: splice every selected (locomotion, action) pair into a new database."""

from .select import parse_selector, select_clips
from .splice_all import JobConfig, JobSummary, SpliceJob

__all__ = ["JobConfig", "JobSummary", "SpliceJob", "select_clips", "parse_selector"]
