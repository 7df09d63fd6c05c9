"""The database job: splice every selected (locomotion, action) pair into a new database.

Rooms: :mod:`.config` (what to splice and how to run it), :mod:`.plan` (pairs, tasks, skips),
:mod:`.sources` (clips read and prepared once), :mod:`.task` (one task's splice),
:mod:`.executors` (engines: this process, local workers, Ray), :mod:`.sink` (shards and the
merged output), :mod:`.splice_all` (the job that drives them).
"""

from .config import JobConfig
from .select import parse_selector, select_clips
from .splice_all import JobSummary, SpliceJob, merge_job

__all__ = ["JobConfig", "JobSummary", "SpliceJob", "merge_job", "select_clips", "parse_selector"]
