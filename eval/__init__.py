"""Metrics, per-scene reports and benchmarks."""
