"""Dataset specs: which joints of a dataset's skeleton play which role, and what its clips are.

- :mod:`.roles`: :class:`SkeletonRoles`, a spec bound to one skeleton (integer joint indices),
  the domain type the splicer, kinematics and evaluation read;
- :mod:`.spec`: :class:`DatasetSpec` (roles by joint name, axes, units, clip rules);
- :mod:`.loading`: :func:`load_spec` and :func:`list_specs` (shipped specs, TOML files),
  :func:`guess_spec` (the ``generic`` spec) and :func:`detect_spec`.

Underneath, from the bottom up (each module imports only those before it):
:mod:`.vocabulary` (roles, units, axes, keys), :mod:`.roles`, :mod:`.clips` (:class:`RoleRule`),
:mod:`.parsing` (TOML and JSON tables into a spec's fields), :mod:`.guess` (the joint-guessing
heuristics), :mod:`.spec`, :mod:`.loading`.

Example::

    from torchsplice.specs import load_spec
    spec = load_spec("bandai_namco")
    roles = spec.bind(motion.skeleton)          # SkeletonRoles, integer joint indices
    role, labels = spec.clip_metadata("dataset-1_walk_proud_001")
    # ("both", {"dataset": "1", "content": "walk", "style": "proud", "take": "001"})
"""

from .clips import RoleRule
from .loading import detect_spec, guess_spec, list_specs, load_spec
from .roles import SkeletonRoles, bind_roles
from .spec import DatasetSpec
from .vocabulary import GENERIC, ROLES, UNITS

__all__ = [
    "DatasetSpec",
    "RoleRule",
    "SkeletonRoles",
    "ROLES",
    "UNITS",
    "GENERIC",
    "load_spec",
    "list_specs",
    "guess_spec",
    "detect_spec",
    "bind_roles",
]
