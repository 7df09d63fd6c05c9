"""Core types: rotations (WXYZ quaternions), skeletons, motion clips and user-facing errors.

The errors import at once; the torch-based types on first use.
"""

from .errors import (BVHError, DatabaseError, MotionError, NotLocomotingError, OutputExistsError, SpecError,
                     TorchspliceError, UnfinishedJobError)

__all__ = ["Motion", "Skeleton", "TorchspliceError", "BVHError", "DatabaseError", "SpecError", "MotionError",
           "NotLocomotingError", "OutputExistsError", "UnfinishedJobError"]


def __getattr__(name):
    if name == "Motion":
        from .motion import Motion

        return Motion
    if name == "Skeleton":
        from .skeleton import Skeleton

        return Skeleton
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
