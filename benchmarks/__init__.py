"""Benchmarks: each module is a command (``python -m benchmarks.<name>``) that prints its
results and writes them to JSON; ``python -m benchmarks.results`` makes RESULTS.md of them.

The thread settings of the command-line entry points apply here too, before any module loads
torch or numba: without them benchmarks on one machine spin in each other's OpenMP waits (two
trainings of the real scenes beside a test run took 3-5 s a step, against 0.3 s alone)."""

from dataset_tools.infra.threads import configure_threads

configure_threads()
