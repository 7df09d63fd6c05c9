"""torchsplice: splice upper-body actions onto locomotion, for every pair of clips in a database.

Conventions (stated once here and in every docstring that uses them): quaternions are unit
quaternions in WXYZ order (scalar first); rotation matrices act on column vectors; Euler
angles follow BVH channel order; lengths are in the source file's units; the up axis is the
one the dataset spec names (Y for every shipped dataset).
"""

__version__ = "0.1.0"

from .core import BVHError, DatabaseError, Motion, MotionError, Skeleton, SpecError, TorchspliceError
from .kinematics import forward_kinematics

__all__ = [
    "__version__", "Motion", "Skeleton", "forward_kinematics",
    "TorchspliceError", "BVHError", "DatabaseError", "SpecError", "MotionError",
]
