"""Benchmark: ``gseval paper-tables --quick`` with ``--engine local`` and ``--engine ray`` (a
local Ray cluster started by the command) side by side: wall time, speed-up, whether the two
tables are the same, and the tables. Prints and writes JSON.

    python -m benchmarks.engine_speed [--work /tmp/gsseg-engine] [--out engine_speed.json]
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import time
from pathlib import Path

from benchmarks import record
from eval.report import markdown_table


def tables(out: Path, engine: str) -> tuple[float, str]:
    """Seconds of a fresh ``paper-tables --quick`` run on ``engine``, and its markdown."""
    shutil.rmtree(out, ignore_errors=True)
    start = time.perf_counter()
    subprocess.run(
        [str(Path(sys.executable).parent / "gseval"), "paper-tables", "--quick", "--out", str(out), "--engine", engine],
        check=True,
        capture_output=True,
    )
    return time.perf_counter() - start, (out / "paper_tables.md").read_text()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--work", type=Path, default=Path("/tmp/gsseg-engine"))
    parser.add_argument("--out", default=None, help="JSON file (default: benchmarks/results/engine_speed.json).")
    args = parser.parse_args()
    local_s, local_md = tables(args.work / "local", "local")
    ray_s, ray_md = tables(args.work / "ray", "ray")
    out = {
        "local_s": local_s,
        "ray_s": ray_s,
        "speedup": local_s / ray_s,
        "same_tables": local_md == ray_md,
        "tables": local_md,
    }
    print(json.dumps(out, indent=2))
    record.save("engine_speed", out, out=args.out)


def report(r: dict) -> tuple[str, str]:
    headline = (
        f"paper-tables --quick: local {r['local_s'] / 60:.1f} min, ray {r['ray_s'] / 60:.1f} min "
        f"({r['speedup']:.2f}x); same tables: {r['same_tables']}"
    )
    return headline, (
        "Both on this machine, the Ray cluster a local one started by the command; each task asks for "
        "the CPUs of a local run, so on one machine the tasks run one at a time.\n\n"
        + markdown_table(
            ["engine", "minutes"],
            [["local", f"{r['local_s'] / 60:.1f}"], ["ray", f"{r['ray_s'] / 60:.1f} ({r['speedup']:.2f}x)"]],
        )
        + f"\n\nSame tables: {r['same_tables']}."
        + (_tables(r["tables"]) if "tables" in r else "")
    )


def _tables(md: str) -> str:
    """The tables of the local run, their headings one level under this benchmark's."""
    lines = [line for line in md.splitlines() if not line.startswith("## ")]
    return (
        "\n\nThe tables (`--engine local`):\n\n"
        + "\n".join("#" + line if line.startswith("### ") else line for line in lines).strip()
    )


if __name__ == "__main__":
    main()
