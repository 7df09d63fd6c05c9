"""Core types: rotations (WXYZ quaternions), skeletons, motion clips and user-facing errors."""

from .errors import BVHError, DatabaseError, MotionError, SpecError, TorchspliceError
from .motion import Motion
from .skeleton import Skeleton

__all__ = ["Motion", "Skeleton", "TorchspliceError", "BVHError", "DatabaseError", "SpecError", "MotionError"]
