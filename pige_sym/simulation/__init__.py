"""Synthetic measurements on a machine with known errors (truth sidecars)."""
