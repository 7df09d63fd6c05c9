"""The npz export's feature sets: the extra per-frame arrays each adds (with statistics). Kept
apart from :mod:`.npz` (which loads torch) so that the command line lists them at once."""

__all__ = ["FEATURE_SETS"]

FEATURE_SETS = {"6d": ("rotations_6d", "velocities", "trajectory_velocity", "root_velocity")}
"""``features`` choices of the npz export: the extra per-frame arrays they add (with statistics)."""
