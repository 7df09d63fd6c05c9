"""Alignment: frame distances, dynamic-programming timewarp, alignment curves and Horn rotations."""
