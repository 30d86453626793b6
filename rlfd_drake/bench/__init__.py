"""Benchmarks behind `rlfd bench ...`; each writes JSON to results/."""
