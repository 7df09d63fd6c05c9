"""torchsplice: splice upper-body actions onto locomotion, for every pair of clips in a database.

Conventions (stated once here and in every docstring that uses them): quaternions are unit
quaternions in WXYZ order (scalar first); rotation matrices act on column vectors; Euler
angles follow BVH channel order; lengths are in the source file's units; the up axis is the
one the dataset spec names (Y for every shipped dataset).

The names below are imported on first use, so that ``import torchsplice`` (and the command
line) starts without loading torch until it is needed.
"""

import os as _os

from .core.version import __version__

# Bit-identical results whatever the machine is doing: MKL (torch's BLAS on x86) may pick
# another code path for the same matrix product depending on how its inputs happen to be
# aligned in memory, which changes the last bits of distance grids; its conditional numerical
# reproducibility mode fixes the path. It must be set before torch loads MKL, so it is set
# here, on first import of the package (the command line imports torch only later).
_os.environ.setdefault("MKL_CBWR", "AUTO")

__all__ = [
    "__version__", "import_bvh", "splice", "splice_all", "export_clips", "MotionDatabase", "MotionDataset",
    "write_sample", "Motion", "Skeleton", "forward_kinematics",
    "TorchspliceError", "BVHError", "DatabaseError", "SpecError", "MotionError", "OutputExistsError",
    "NotLocomotingError", "UnfinishedJobError", "LockedError",
]

from .core.lazy import lazy_names  # noqa: E402 (after the environment is set)

# The main verbs, then the core types. ``splice`` is the package torchsplice.splice, callable as
# torchsplice.splice.api.splice (see torchsplice/splice/__init__.py).
__getattr__, __dir__ = lazy_names(__name__, {
    "import_bvh": ".formats.importer", "splice": ".splice", "splice_all": ".job.run", "export_clips": ".formats.exporters",
    "MotionDatabase": ".store.database", "MotionDataset": ".data.dataset",
    "write_sample": ".formats.sample_database",
    "Motion": ".core.motion", "Skeleton": ".core.skeleton", "forward_kinematics": ".core.fk",
    "TorchspliceError": ".core.errors", "BVHError": ".core.errors", "DatabaseError": ".core.errors",
    "SpecError": ".core.errors", "MotionError": ".core.errors", "OutputExistsError": ".core.errors",
    "NotLocomotingError": ".core.errors", "UnfinishedJobError": ".core.errors", "LockedError": ".core.errors",
})

