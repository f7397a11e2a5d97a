"""Batch sweeps: `sweep` (plan, lanes, reductions, sharding) and the maps built on it."""
