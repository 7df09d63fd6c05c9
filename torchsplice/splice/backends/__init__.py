"""Splicing backends: one interface for a batch of pairs (filled in below)."""
