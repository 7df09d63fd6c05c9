"""The built-in synthetic sample: procedurally generated locomotions and actions on a standard
22-joint skeleton (Y up, centimetres, 30 fps), made by :mod:`.generate`; no data needed.

    from torchsplice.sample import sample_motions
    motions = sample_motions()                  # list of Motion, deterministic
"""

from .clips import SAMPLE_CLIPS
from .generate import SAMPLE_FPS, SAMPLE_SOURCE, sample_motions, sample_motion
from .skeleton import sample_skeleton

__all__ = ["SAMPLE_FPS", "SAMPLE_SOURCE", "SAMPLE_CLIPS", "sample_skeleton", "sample_motions", "sample_motion"]
