"""Least squares: the PIGEs with uncertainty and identifiability, and the studies built on it."""
