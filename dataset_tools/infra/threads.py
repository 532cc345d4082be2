"""The CPUs a process may use, and the thread settings of the numeric libraries.

torch and numba's ``omp`` threading layer both run on GNU OpenMP, whose idle workers spin
for a while before they sleep. Alone on a machine that spinning buys a little latency;
beside other heavy processes it burns CPU time that makes no progress (two demos at once
took five times the CPU seconds of one). The command-line entry points therefore ask idle
workers to sleep at once (``OMP_WAIT_POLICY=PASSIVE``) and size every pool to the CPUs the
process may really use: its affinity mask, capped by a cgroup CPU quota (containers).
A setting the user made in the environment is kept.
"""

from __future__ import annotations

import math
import os
from collections.abc import MutableMapping
from pathlib import Path

THREAD_VARIABLES = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS")


def cgroup_cpu_limit(root: Path = Path("/sys/fs/cgroup")) -> float | None:
    """The CPU quota of the process's cgroup in CPUs (cgroup v2 ``cpu.max``, or v1
    ``cpu.cfs_quota_us`` / ``cpu.cfs_period_us``); None without a quota."""
    try:
        quota, period = (root / "cpu.max").read_text().split()[:2]
        return None if quota == "max" else int(quota) / int(period)
    except (OSError, ValueError):
        pass
    try:
        quota = int((root / "cpu" / "cpu.cfs_quota_us").read_text())
        period = int((root / "cpu" / "cpu.cfs_period_us").read_text())
        return None if quota <= 0 else quota / period
    except (OSError, ValueError):
        return None


def usable_cpus() -> int:
    """CPUs this process may use: its affinity mask, capped by the cgroup quota (rounded up)."""
    cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
    limit = cgroup_cpu_limit()
    return max(1, min(cpus, math.ceil(limit))) if limit else cpus


def configure_threads(environ: MutableMapping[str, str] = os.environ) -> int:
    """Set the thread variables of :data:`THREAD_VARIABLES` to :func:`usable_cpus` and
    ``OMP_WAIT_POLICY`` to ``PASSIVE`` where the user has not set them, and OpenCV's pool to
    the same size. Call it before torch, numba or onnxruntime are imported (they read the
    variables once). Returns the thread count."""
    cpus = usable_cpus()
    for name in THREAD_VARIABLES:
        environ.setdefault(name, str(cpus))
    environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
    import cv2

    cv2.setNumThreads(int(environ["OMP_NUM_THREADS"]))
    return cpus
