"""The fork server's preload (:mod:`torchsplice.job.worker`): a backend whose preload fails is
named in one line, and the others are still preloaded."""

from __future__ import annotations

import io

from torchsplice.job.worker import preload_backends
from torchsplice.splice.backends import available_backends, get_backend


def test_a_failed_preload_is_named_in_one_line_and_the_others_still_run(monkeypatch):
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
    out = io.StringIO()
    assert preload_backends(out) == [] and out.getvalue() == ""
