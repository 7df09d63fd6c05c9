"""The database job: splice every selected (locomotion, action) pair into a new database.

Rooms: :mod:`.config` (what to splice and how to run it), :mod:`.plan` (pairs, tasks, skips),
:mod:`.sources` (clips read and prepared once), :mod:`.task` (one task's splice),
:mod:`.executors` (engines: this process, local workers, Ray), :mod:`.sink` (shards and the
merged output), :mod:`.run` (the job that drives them).

From Python, :func:`splice_all` runs the whole job with the command line's selections and
options (:class:`JobConfig` fields) and returns the :class:`JobSummary`::

    from torchsplice.job import splice_all
    summary = splice_all("bandai.h5", "spliced.h5", locomotions="role:locomotion", methods="splice,naive")
"""

from .config import JobConfig, job_config
from .run import JobSummary, SpliceJob, merge_job, splice_all
from .select import parse_selector, select_clips

__all__ = ["splice_all", "JobConfig", "job_config", "JobSummary", "SpliceJob", "merge_job", "select_clips",
           "parse_selector"]
