"""What the PIGE model misses: candidate effects, selection, outliers, results."""
