"""The limits reading and writing BVH share: what a file torchsplice reads or writes may hold."""

__all__ = ["MAX_JOINTS", "MIN_FRAME_TIME", "MAX_FRAME_TIME", "MAX_ABS_VALUE"]

MAX_JOINTS = 10_000  # more joints than any real skeleton: a file past it is refused
MIN_FRAME_TIME, MAX_FRAME_TIME = 0.001, 1.0  # seconds: 1,000 fps to 1 fps
MAX_ABS_VALUE = 1e12  # an OFFSET or channel value beyond this is refused as absurd
