"""Simulated study campaigns that measure the diagnosis itself (attribution, nulls, timing) on
the virtual bench: used by the tests, the benchmarks and ``python -m labrig.studies.campaign``."""
