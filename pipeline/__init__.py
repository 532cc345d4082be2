"""Whole runs on top of the stages: the demo, the experiment steps the benchmarks share, and
the paper tables. Nothing below this layer imports it."""
