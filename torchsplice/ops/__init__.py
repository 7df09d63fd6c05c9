"""Transforms on clips: unit conversion (:mod:`.units`)."""
