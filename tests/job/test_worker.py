"""The fork server's preload (:mod:`torchsplice.job.worker`): a backend whose preload fails is
named in one line, and the others are still preloaded."""

from __future__ import annotations

import io
import subprocess
import sys

import pytest

from torchsplice.splice.backends import available_backends, get_backend


@pytest.fixture
def preload_backends(monkeypatch):
    """:func:`torchsplice.job.worker.preload_backends`, its module imported (which preloads) with
    every backend's preload stubbed. The compiled backend's real one readies numba for a fork
    server (the ``workqueue`` threading layer, which survives a fork but aborts where two threads
    launch kernels at once, as a thread engine does), so it runs in a process of its own here
    (:func:`test_a_good_preload_says_nothing`), not in the one that runs the other tests."""
    for name in available_backends():
        monkeypatch.setattr(get_backend(name), "preload", lambda: None)
    from torchsplice.job.worker import preload_backends

    return preload_backends


def test_a_failed_preload_is_named_in_one_line_and_the_others_still_run(preload_backends, monkeypatch):
    names = [n for n in available_backends() if get_backend(n).available()]
    assert "compiled" in names and len(names) >= 2
    ran = []
    for name in names:
        backend = get_backend(name)
        if name == "compiled":
            def fail():
                raise TypeError("Signature mismatch: 29 argument types given, but function takes 30 arguments")
            monkeypatch.setattr(backend, "preload", fail)
        else:
            monkeypatch.setattr(backend, "preload", lambda name=name: ran.append(name))
    out = io.StringIO()
    lines = preload_backends(out)
    assert len(lines) == 1 and out.getvalue() == lines[0] + "\n"
    assert "'compiled'" in lines[0] and "TypeError: Signature mismatch" in lines[0] and "\n" not in lines[0]
    assert sorted(ran) == sorted(n for n in names if n != "compiled")


def test_a_good_preload_says_nothing():
    """As a fork server starts: the module's import preloads every backend, and so does a call."""
    code = ("import io\nfrom torchsplice.job.worker import preload_backends\nout = io.StringIO()\n"
            "print(preload_backends(out) == [] and out.getvalue() == '')")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0 and done.stdout.strip() == "True" and done.stderr == "", done.stderr
