"""Splicing methods: the Heck-Kovar-Gleicher splice and the naive and CPMC baselines, for
actions that locomote (time-aligned) and for standing actions (looped, held or fitted), and
the method registry (:mod:`.registry`) that plug-in methods join.

The names below are imported on first use, so that the registry (and the command line) can be
read without loading torch.
"""

__all__ = ["TIMINGS", "AlignOptions", "SpliceOptions", "SpliceResult", "NotLocomotingError", "splice",
           "splice_pairs", "splice_standing", "Method", "MethodInput", "MethodOutput", "register_method",
           "get_method", "available_methods", "load_plugins"]

_LAZY = {
    "TIMINGS": "standing", "SpliceOptions": "options", "SpliceResult": "api", "NotLocomotingError": "api", "splice": "api",
    "splice_pairs": "api", "splice_standing": "api", "AlignOptions": "heck",
    "Method": "registry", "MethodInput": "registry", "MethodOutput": "registry", "register_method": "registry",
    "get_method": "registry", "available_methods": "registry", "load_plugins": "registry",
}


def __getattr__(name):
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
