"""Hostile inputs for the surfaces past the BVH parser (``bvh_corpus.py`` covers the parser):
clip names, plug-in methods and their results.

- :data:`CONTROL_NAMES`: clip names holding control characters (escape sequences that clear
  the screen, set the window title or forge an output line; bell, newline, DEL, C1, a
  bidirectional override). Every writer refuses them, naming the character.
- :data:`MARKUP_NAMES`: legal clip names that are Markdown or HTML (an image with a script,
  an SVG with ``onload``, a comment that hides the rest of a page, a table pipe, a link, code
  spans, emphasis, a heading or list at the start). They are stored as they are and shown as
  plain text everywhere: reports, the viewer, the terminal.
- :data:`FILE_NAMES`: legal clip names that are not safe file names everywhere (Windows'
  reserved devices and punctuation, names equal but for case): exports make them safe and
  unique without regard to case.
- :data:`HOSTILE_METHODS`: plug-in methods that misbehave (NaN, a raise, ``sys.exit``, a
  100,000-character message with escape sequences, times of the wrong shape, zero and huge
  quaternions, integer, boolean and complex dtypes, tensors on the ``meta`` device), each with
  what the refusal says.

The kill points of a job (mid-install of a virtual output's shards, after it) are injected in
``test_adversary_virtual.py``; those of a resumed job in ``test_job.py`` and ``test_job_disk.py``.
"""

from __future__ import annotations

from dataclasses import replace

import torch

from torchsplice.splice.registry import MethodOutput

__all__ = ["CONTROL_NAMES", "MARKUP_NAMES", "FILE_NAMES", "HOSTILE_METHODS", "rotations_through"]

CONTROL_NAMES = {  # name -> the control character an error must name
    "clear\x1b[2J\x1b[H": "U+001B",
    "title\x1b]0;owned\x07": "U+001B",
    "bell\x07": "U+0007",
    "forged\nwrote out.h5: 0 clips": "U+000A",
    "tab\tname": "U+0009",
    "del\x7f": "U+007F",
    "csi\x9b2J": "U+009B",
    "gnp.exe\u202e": "U+202E",
}

MARKUP_NAMES = [
    "<img src=x onerror=alert(1)>",
    "<svg onload=alert(1)>",
    "<!-- hidden",
    "pipe|cell",
    "[link](javascript:alert(1))",
    "`code` and **bold** _em_",
    "# heading",
    "- item",
    "&amp; entity",
]

FILE_NAMES = ["CON", "nul", "a:b", "a?b", "star*", "quote\"d", "dup", "DUP", "Dup", "trailing.", "lt<gt>"]


def _nan_run(inp):
    """The locomotion, with frame 3 of every pair's rotations NaN."""
    rot = inp.loco.rotations.clone()
    rot[:, 3] = float("nan")
    return MethodOutput(replace(inp.loco, rotations=rot), inp.loco.rotations.new_zeros(rot.shape[:2]).double())


def _raising_run(inp):
    raise RuntimeError("boom inside the plug-in")


def _short_times(inp):
    """Times of the wrong shape: (B, 3) instead of (B, T)."""
    return MethodOutput(inp.loco, inp.loco.rotations.new_zeros(inp.loco.rotations.shape[0], 3).double())


def rotations_through(fn):
    """A method returning the locomotion with its rotations passed through ``fn``."""
    def run(inp):
        return MethodOutput(replace(inp.loco, rotations=fn(inp.loco.rotations)),
                            inp.loco.rotations.new_zeros(inp.loco.rotations.shape[:2]).double())
    return run


def _exits(inp):
    raise SystemExit(3)


def _shouts(inp):
    raise ValueError("\x1b[2J\x1b]0;owned\x07" + "spam " * 20000)


HOSTILE_METHODS = {  # method name -> (its function, what the skip reason says)
    "adv_nan": (_nan_run, "not finite"),
    "adv_raises": (_raising_run, "boom inside the plug-in"),
    "adv_times": (_short_times, "times"),
    "adv_zero": (rotations_through(lambda r: r * 0), "not unit quaternions"),
    "adv_huge": (rotations_through(lambda r: r * 1e30), "not unit quaternions"),
    "adv_int": (rotations_through(lambda r: r.round().int()), "rotations of type torch.int32, not floating point"),
    "adv_bool": (rotations_through(lambda r: r > 0), "rotations of type torch.bool, not floating point"),
    "adv_complex": (rotations_through(lambda r: r.to(torch.complex64)), "not floating point"),
    "adv_meta": (rotations_through(lambda r: r.to("meta")), "meta device"),
    "adv_exits": (_exits, "called sys.exit(3)"),
    "adv_shouts": (_shouts, "ValueError: \\x1b[2J"),
}
