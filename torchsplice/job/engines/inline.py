"""The engine of this process: the job's tasks one after another (one worker, or a CUDA
device). A background thread writes each task's shard (when kept) and hands it over while the
next one computes."""

from __future__ import annotations

from concurrent.futures import Future, ThreadPoolExecutor

from ..task import run_task
from .base import Engine

__all__ = ["InlineEngine"]


class InlineEngine(Engine):
    """Tasks in this process, one after another (see the module docstring)."""

    name = "inline"

    def describe(self) -> str:
        backend = self.config.splice_backend()
        if backend.prepares_once:
            n = backend.threads()
            return f"this process ({n} compute thread{'s' if n != 1 else ''})"
        return f"this process (torch on {self.config.device or 'cpu'})"

    def run(self, tasks, done) -> None:
        backend = self.config.splice_backend()
        buffers = (backend.new_buffers(), backend.new_buffers())  # the writer reads one while the next task fills the other
        if buffers[0] is None:
            buffers = None
        pending: Future | None = None

        def write(task, part):  # in the writer thread, while the next task computes
            self.ctx.write_shard(task, part)
            done(task, part)

        with ThreadPoolExecutor(max_workers=1) as writer:
            try:
                for n, task in enumerate(tasks):
                    part = run_task(self.plan, task, self.ctx.sources, self.config, buffers[n % 2] if buffers else None)
                    if pending is not None:
                        pending.result()
                    pending = writer.submit(write, task, part)
                if pending is not None:
                    pending.result()
            except BaseException:
                while pending is not None and not pending.done():
                    try:
                        pending.result()  # keep the task being written (a second Ctrl-C waits on)
                    except KeyboardInterrupt:
                        continue
                    except BaseException:
                        break
                raise
