"""Where benchmark results go: one JSON file per benchmark run in ``benchmarks/results/``,
holding the results with the command that produced them, the date, the machine and the
commit. ``python -m benchmarks.results`` renders ``benchmarks/RESULTS.md`` from those files.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import shlex
import subprocess
import sys
from pathlib import Path

import torch

from dataset_tools.infra.atomic import write_bytes_atomic
from dataset_tools.infra.errors import InputError
from dataset_tools.infra.overlap import refuse_overlap

RESULTS = Path(__file__).resolve().parent / "results"


def commit() -> str:
    """The checked-out commit, with ``+changes`` when the tree differs from it. Result files are
    outputs, not code: a benchmark that saves after each finished run must not mark itself."""
    root = Path(__file__).resolve().parents[1]
    try:
        head = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], cwd=root, capture_output=True, text=True, check=True
        ).stdout.strip()
        dirty = subprocess.run(
            [
                "git",
                "status",
                "--porcelain",
                "--untracked-files=no",
                "--",
                ".",
                f":(exclude){RESULTS.relative_to(root)}",
            ],
            cwd=root,
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"
    return head + ("+changes" if dirty else "")


def machine() -> str:
    """CPU cores this process may use, the CPU, and the GPU where one is present."""
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    gpu = f", {torch.cuda.get_device_name(0)}" if torch.cuda.is_available() else ", no GPU"
    return f"{cores} cores ({cpu}){gpu}"


def provenance() -> dict:
    """The command line, date (UTC), machine and commit of this benchmark run."""
    module = Path(sys.argv[0]).with_suffix("").name
    command = " ".join(["python -m benchmarks." + module, *map(shlex.quote, sys.argv[1:])])
    return {
        "command": command,
        "date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d"),
        "machine": machine(),
        "commit": commit(),
    }


def out_path(benchmark: str, *, tag: str = "", out: str | Path | None = None) -> Path:
    """Where :func:`save` writes: ``out``, or ``benchmarks/results/<benchmark>[-tag].json``."""
    return Path(out) if out else RESULTS / f"{benchmark}{'-' + tag if tag else ''}.json"


def refuse_out_inside(
    parser: argparse.ArgumentParser, benchmark: str, work: Path, *, tag: str = "", out: str | Path | None = None
) -> None:
    """Stop the command line of ``parser`` (exit 2, one sentence) where :func:`out_path` lies
    inside the folder ``work`` of the scenes and runs the benchmark reads: a benchmark never
    writes over what it reads."""
    try:
        refuse_overlap(out_path(benchmark, tag=tag, out=out), [("the work folder", work)])
    except InputError as err:
        parser.error(str(err))


def save(benchmark: str, results: dict, *, tag: str = "", out: str | Path | None = None) -> Path:
    """Write ``results`` with their provenance to :func:`out_path` and print where. Returns
    the path."""
    path = out_path(benchmark, tag=tag, out=out)
    data = {"benchmark": benchmark, **provenance(), "results": results}
    write_bytes_atomic(path, (json.dumps(data, indent=2) + "\n").encode())
    print(f"wrote {path}")
    return path
