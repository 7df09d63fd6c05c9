"""Splicing methods: the Heck-Kovar-Gleicher splice and the naive and CPMC baselines, for
actions that locomote (time-aligned) and for standing actions (looped, held or fitted), and
the method registry (:mod:`.registry`) that plug-in methods join.

The names below are imported on first use, so that the registry (and the command line) can be
read without loading torch.
"""

__all__ = ["TIMINGS", "AlignOptions", "SpliceOptions", "SpliceResult", "NotLocomotingError", "splice",
           "splice_pairs", "splice_standing", "Method", "MethodInput", "MethodOutput", "register_method",
           "get_method", "available_methods", "load_plugins"]

import sys as _sys
import types as _types

from ..core.lazy import lazy_names

__getattr__, __dir__ = lazy_names(__name__, {
    "TIMINGS": ".defaults", "SpliceOptions": ".options", "SpliceResult": ".api", "NotLocomotingError": ".api",
    "splice": ".api", "splice_pairs": ".api", "splice_standing": ".api", "AlignOptions": ".options",
    "Method": ".registry", "MethodInput": ".registry", "MethodOutput": ".registry", "register_method": ".registry",
    "get_method": ".registry", "available_methods": ".registry", "load_plugins": ".registry",
})


class _SplicePackage(_types.ModuleType):
    """This package, callable as its main verb: ``from torchsplice import splice`` gives the
    package, and ``splice(locomotion, action, spec, ...)`` is :func:`torchsplice.splice.api.splice`
    (one name for both, as ``torchsplice.splice.registry`` and friends must stay reachable)."""

    def __call__(self, *args, **kwargs):
        return self.__getattr__("splice")(*args, **kwargs)


_sys.modules[__name__].__class__ = _SplicePackage
