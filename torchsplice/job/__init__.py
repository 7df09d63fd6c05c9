"""The database job: splice every selected (locomotion, action) pair into a new database.

Rooms: :mod:`.config` (what to splice and how to run it), :mod:`.plan` (pairs, tasks, skips),
:mod:`.sources` (clips read and prepared once), :mod:`.task` (one task's splice), :mod:`.engines`
(what runs the tasks: this process, local workers, Ray, or a registered engine), :mod:`.sink`
(shards into the output), :mod:`.merge` (the staged output, :func:`merge_job`), :mod:`.shards`
(slices and a virtual output's shards), :mod:`.size`, :mod:`.summary` (:class:`JobSummary`),
:mod:`.run` (the job that drives them), :mod:`.pair` (one pair of a database, :func:`splice_pair`).
Clips are chosen by :mod:`torchsplice.store.select`.

From Python, :func:`splice_all` runs the whole job with the command line's selections and
options (:class:`JobConfig` fields) and returns the :class:`JobSummary`::

    from torchsplice.job import splice_all
    summary = splice_all("bandai.h5", "spliced.h5", locomotions="role:locomotion", methods="splice,naive")
"""

from ..core.lazy import lazy_names

__all__ = ["splice_all", "JobConfig", "job_config", "JobSummary", "SpliceJob", "merge_job", "select_clips",
           "parse_selector", "splice_pair"]

# imported when first used: the command line reads the engine registry (.engines) without torch
__getattr__, __dir__ = lazy_names(__name__, {
    "JobConfig": ".config", "job_config": ".config", "JobSummary": ".summary", "SpliceJob": ".run",
    "merge_job": ".merge", "splice_all": ".run", "parse_selector": "..store.select", "select_clips": "..store.select",
    "splice_pair": ".pair"})
