"""Reproducible performance measurements of labrig (not tests); see benchmarks/RESULTS.md."""
