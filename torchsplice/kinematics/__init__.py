"""Kinematics: batched forward kinematics and quantities derived from joint positions."""

from ..core.fk import end_site_positions, forward_kinematics

__all__ = ["forward_kinematics", "end_site_positions"]
