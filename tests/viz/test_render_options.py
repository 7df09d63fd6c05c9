""":func:`~torchsplice.viz.render.render`'s options as one :class:`~torchsplice.viz.render.RenderOptions`:
the same defaults as its keywords, and the same bytes written through either."""

from __future__ import annotations

import dataclasses
import inspect

import pytest
import torch

from torchsplice.core.errors import TorchspliceError
from torchsplice.sample import sample_motion
from torchsplice.viz.render import RenderOptions, render, render_clips
from torchsplice.viz.writers import GIF_DPI


def test_the_options_defaults_are_renders_keyword_defaults():
    """Every option is one of :func:`render`'s keywords, with its default, and every keyword but
    the clips, the output and the titles is an option."""
    keywords = {n: p.default for n, p in inspect.signature(render).parameters.items()
                if n not in ("motions", "output", "titles")}
    assert {f.name: f.default for f in dataclasses.fields(RenderOptions)} == keywords


@pytest.mark.parametrize("name", ["strip.png", "anim.gif"])
def test_render_and_render_clips_write_the_same_bytes(tmp_path, name):
    walk = sample_motion("walk_straight", dtype=torch.float64).slice(0, 20)
    box = sample_motion("carry_box", dtype=torch.float64).slice(0, 15)
    kw = dict(frames=3, size=1.2, dpi=40, max_seconds=0.5, azimuth=-70.0, elevation=15.0, camera="world")
    a = render([walk, [box, walk]], tmp_path / f"a_{name}", titles=["w", "b"], **kw)
    b = render_clips([walk, [box, walk]], tmp_path / f"b_{name}", RenderOptions(**kw), titles=["w", "b"])
    assert a.read_bytes() == b.read_bytes()


def test_the_options_are_checked_in_one_place():
    with pytest.raises(TorchspliceError, match="camera must be one of"):
        RenderOptions(camera="orbit").checked(".png")
    with pytest.raises(TorchspliceError, match="size and dpi must be positive"):
        RenderOptions(size=0.0).checked(".gif")
    assert RenderOptions(up_axis="z").checked(".gif") == (2, GIF_DPI)
    assert RenderOptions().checked(".png") == (1, 100) and RenderOptions(dpi=72).checked(".gif") == (1, 72)
