"""Experiments over many runs: sweeps (Table I), the trade-off checks, the interval audit,
provenance."""
