"""Core types: rotations (WXYZ quaternions), skeletons, motion clips and user-facing errors.

The errors import at once; the torch-based types on first use.
"""

from .errors import (
    BVHError,
    DatabaseError,
    MotionError,
    NotLocomotingError,
    OutputExistsError,
    SpecError,
    TorchspliceError,
    UnfinishedJobError,
)
from .lazy import lazy_names

__all__ = [
    "Motion",
    "Skeleton",
    "TorchspliceError",
    "BVHError",
    "DatabaseError",
    "SpecError",
    "MotionError",
    "NotLocomotingError",
    "OutputExistsError",
    "UnfinishedJobError",
]


__getattr__, __dir__ = lazy_names(__name__, {"Motion": ".motion", "Skeleton": ".skeleton"})
