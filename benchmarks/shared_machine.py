"""Benchmark: fairness on a shared machine. ``gsseg demo`` alone, then two demos at once:
wall time and CPU seconds (user + system, from each process's own resource usage), with the
entry points' thread settings (idle OpenMP workers sleep) and with GNU OpenMP's default wait
policy (they spin first) side by side. Prints and writes JSON.

    python -m benchmarks.shared_machine [--iters 1500] [--work /tmp/gsseg-shared] [--out shared_machine.json]

Bounds: two at once take at most 2.3x the wall time of one alone, and their CPU seconds stay
within 1.3x of twice one alone's.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

from benchmarks import record
from eval.report import markdown_table

POLICIES = {"passive (the entry points' default)": {}, "spin first (GNU OpenMP's default)": {"OMP_WAIT_POLICY": ""}}


def demos(work: Path, count: int, iters: int, env: dict[str, str]) -> dict:
    """Run ``count`` demos at once; their wall time (the slowest) and CPU seconds (summed)."""
    gsseg = str(Path(sys.executable).parent / "gsseg")
    start = time.perf_counter()
    procs = []
    for i in range(count):
        out = work / f"demo_{i}"
        shutil.rmtree(out, ignore_errors=True)
        with open(work / f"demo_{i}.log", "wb") as log:  # a file, not a pipe: a full pipe would stall the demo
            procs.append(
                subprocess.Popen(
                    [gsseg, "demo", "--out", str(out), "--iters", str(iters)],
                    stdout=log,
                    stderr=subprocess.STDOUT,
                    env={**os.environ, **env},
                )
            )
    cpu = 0.0
    walls = []
    for i, proc in enumerate(procs):
        _, status, usage = os.wait4(proc.pid, 0)
        walls.append(time.perf_counter() - start)
        if os.waitstatus_to_exitcode(status) != 0:
            raise SystemExit(f"a demo failed; see {work / f'demo_{i}.log'}")
        cpu += usage.ru_utime + usage.ru_stime
    return {"wall_s": max(walls), "cpu_s": cpu}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--iters", type=int, default=1500, help="Training iterations of each demo.")
    parser.add_argument("--work", type=Path, default=Path("/tmp/gsseg-shared"))
    parser.add_argument("--out", default=None, help="JSON file (default: benchmarks/results/shared_machine.json).")
    args = parser.parse_args()
    args.work.mkdir(parents=True, exist_ok=True)
    out = {"iters": args.iters, "policies": {}}
    for name, env in POLICIES.items():
        alone = demos(args.work, 1, args.iters, env)
        pair = demos(args.work, 2, args.iters, env)
        out["policies"][name] = {
            "alone": alone,
            "two_at_once": pair,
            "wall_ratio": pair["wall_s"] / alone["wall_s"],
            "cpu_ratio": pair["cpu_s"] / (2 * alone["cpu_s"]),
        }
        print(json.dumps({name: out["policies"][name]}))
    print(json.dumps(out, indent=2))
    record.save("shared_machine", out, out=args.out)


def report(r: dict) -> tuple[str, str]:
    first, p = next(iter(r["policies"].items()))
    headline = (
        f"two demos at once: {p['wall_ratio']:.2f}x the wall time of one (bound 2.3x), CPU seconds "
        f"{p['cpu_ratio']:.2f}x twice one's (bound 1.3x)"
    )
    table = markdown_table(
        ["idle OpenMP workers", "one demo: wall / CPU", "two at once: wall / CPU", "wall ratio", "CPU ratio"],
        [
            [
                name,
                f"{x['alone']['wall_s']:.0f} s / {x['alone']['cpu_s']:.0f} s",
                f"{x['two_at_once']['wall_s']:.0f} s / {x['two_at_once']['cpu_s']:.0f} s",
                f"{x['wall_ratio']:.2f}x",
                f"{x['cpu_ratio']:.2f}x",
            ]
            for name, x in r["policies"].items()
        ],
    )
    return headline, f"`gsseg demo --iters {r['iters']}`, alone and two at once, per wait policy.\n\n{table}"


if __name__ == "__main__":
    main()
