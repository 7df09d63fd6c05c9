"""Helpers for tests that drive the ``torchsplice`` command line in this process."""

from __future__ import annotations

import pytest

from torchsplice.cli import main


def run(capsys, *argv):
    """``(exit code, stdout, stderr)`` of ``torchsplice ARGV`` (arguments made strings)."""
    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return rc, out, err


def run_any(capsys, *argv):
    """Like :func:`run`, but a usage mistake (the argument parser's ``SystemExit``) gives its exit
    code, and an exception escaping ``main`` fails the test saying so."""
    try:
        code = main([str(a) for a in argv])
    except SystemExit as e:
        code = e.code
    except Exception as exc:  # noqa: BLE001 - a command must not raise
        pytest.fail(f"`torchsplice {' '.join(map(str, argv))}` raised {type(exc).__name__} "
                    f"instead of a one-line error: {exc}")
    out, err = capsys.readouterr()
    return code, out, err


def error_line(err: str) -> str:
    """The single ``torchsplice: error:`` line of a refusal (and no traceback)."""
    assert "Traceback" not in err, err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("torchsplice: error: "), err
    return lines[0]
