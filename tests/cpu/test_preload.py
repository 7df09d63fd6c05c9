"""The kernels a job's worker loads before it forks (:mod:`torchsplice.cpu.preload`) are the ones
a task then calls, with the same argument types: a kernel whose arguments change without its
preload entry fails the preload (which a worker then skips, silently, compiling on first use)."""

from __future__ import annotations

import inspect
import json
import subprocess
import sys
import textwrap

from torchsplice.cpu.preload import job_kernels, preload


def test_every_job_kernel_is_preloaded_with_as_many_arguments_as_it_takes():
    kernels = job_kernels()
    assert len(kernels) >= 8
    for kernel, args in kernels.items():
        takes = len(inspect.signature(kernel.py_func).parameters)
        assert takes == len(args), f"{kernel.py_func.__name__} takes {takes} arguments; its preload gives {len(args)}"
    preload()  # compiles or loads each by its signature, raising on any mismatch


def test_a_job_after_preload_compiles_no_kernel_again(tmp_path):
    """In a fresh process: preload, then splice the built-in sample with every method (standing
    actions included) in that process; no kernel of the table gains a signature."""
    code = textwrap.dedent(f"""
        import json
        from torchsplice.cpu.preload import job_kernels, preload
        preload()
        kernels = job_kernels()
        before = {{k.py_func.__name__: set(map(str, k.signatures)) for k in kernels}}
        from torchsplice import splice_all, write_sample
        write_sample({str(tmp_path / "sample.h5")!r})
        report = splice_all({str(tmp_path / "sample.h5")!r}, {str(tmp_path / "out.h5")!r}, workers=1,
                            methods="splice,naive,cpmc")
        after = {{k.py_func.__name__: set(map(str, k.signatures)) for k in kernels}}
        print(json.dumps({{"new": {{k: sorted(after[k] - before[k]) for k in after if after[k] - before[k]}},
                          "clips": report.spliced}}))
    """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-3000:]
    result = json.loads(out.stdout.strip().splitlines()[-1])
    assert result["clips"] > 0
    assert result["new"] == {}, f"kernels compiled again after the preload: {result['new']}"
