"""Helpers for tests that drive the ``torchsplice`` command line in this process."""

from __future__ import annotations

from torchsplice.cli import main


def run(capsys, *argv):
    """``(exit code, stdout, stderr)`` of ``torchsplice ARGV`` (arguments made strings)."""
    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return rc, out, err


def error_line(err: str) -> str:
    """The single ``torchsplice: error:`` line of a refusal (and no traceback)."""
    assert "Traceback" not in err, err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("torchsplice: error: "), err
    return lines[0]
