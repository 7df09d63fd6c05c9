"""The kernels a job's worker loads before it forks (:mod:`torchsplice.cpu.preload`) are the ones
a task then calls, with the same argument types: a kernel whose arguments change without its
preload entry fails the preload (which a worker then skips, silently, compiling on first use)."""

from __future__ import annotations

import inspect
import json
import subprocess
import sys
import textwrap

import pytest

from torchsplice.cpu.preload import job_kernels, preload


def test_every_job_kernel_is_preloaded_with_as_many_arguments_as_it_takes():
    kernels = job_kernels()
    assert len(kernels) >= 8
    for kernel, args in kernels.items():
        takes = len(inspect.signature(kernel.py_func).parameters)
        assert takes == len(args), f"{kernel.py_func.__name__} takes {takes} arguments; its preload gives {len(args)}"
    preload()  # compiles or loads each by its signature, raising on any mismatch


def _jobs_after_preload(jobs: list[tuple[str, str, dict]]) -> dict:
    """In a fresh process: :func:`preload`, then each job ``(database, output, options)`` of
    ``splice_all`` with one worker (in that process); what each spliced, standing and corrected,
    and the kernels of the table that gained a signature."""
    code = textwrap.dedent(f"""
        import json
        import numpy as np
        from torchsplice.cpu.preload import job_kernels, preload
        from torchsplice.store import MotionDatabase
        preload()
        kernels = job_kernels()
        before = {{k.py_func.__name__: set(map(str, k.signatures)) for k in kernels}}
        from torchsplice import splice_all
        done = []
        for db, out, options in {jobs!r}:
            report = splice_all(db, out, workers=1, **options)
            with MotionDatabase.open(out) as o:
                e = o.clip_table().extra
                done.append({{"clips": report.spliced,
                              "standing": int(sum(t != "timewarp" for t in e["timing"])),
                              "corrected": int((np.asarray(e["corrected_frames"]) > 0).sum())}})
        after = {{k.py_func.__name__: set(map(str, k.signatures)) for k in kernels}}
        print(json.dumps({{"new": {{k: sorted(after[k] - before[k]) for k in after if after[k] - before[k]}},
                          "jobs": done}}))
    """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-3000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_a_job_after_preload_compiles_no_kernel_again(sample_db, tmp_path):
    """The built-in sample spliced with every method: time-aligned pairs, splice, naive and cpmc."""
    result = _jobs_after_preload([(str(sample_db), str(tmp_path / "out.h5"), {"methods": "splice,naive,cpmc"})])
    assert result["jobs"][0]["clips"] > 0
    assert result["new"] == {}, f"kernels compiled again after the preload: {result['new']}"


@pytest.mark.realdata
def test_standing_actions_and_the_hands_correction_after_preload_compile_no_kernel_again(bandai_namco_db, tmp_path):
    """Bandai Namco dashes x waves and raised hands: standing actions, some with a hand moved out
    of the body (the kernels the sample's job never calls)."""
    select = {"locomotions": ["*dash*"], "actions": ["*wave*,*raise*,*bye*,*call*"]}
    result = _jobs_after_preload([(str(bandai_namco_db), str(tmp_path / "out.h5"), select)])
    job = result["jobs"][0]
    assert job["standing"] > 0 and job["corrected"] > 0, job
    assert result["new"] == {}, f"kernels compiled again after the preload: {result['new']}"
