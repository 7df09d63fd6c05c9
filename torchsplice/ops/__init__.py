"""Transforms on clips: unit conversion (:mod:`.units`), retargeting onto another humanoid skeleton (:mod:`.retarget`)."""
