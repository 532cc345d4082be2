"""Benchmark: the analogs of the paper's tables (``gseval paper-tables``) recorded with their
provenance. ``--quick``: one orbit and one forward scene, 16 views at 256², 300 iterations;
without it the full setup (three seeds a path, the CPU schedule: hours on 2 cores). Work is
kept in ``--work`` so an interrupted run resumes.

    python -m benchmarks.paper_tables [--quick] [--work DIR] [--backend auto] [--out FILE]
"""

from __future__ import annotations

import argparse
import json
import re
import tempfile
import time
from pathlib import Path

from benchmarks import record
from pipeline.paper_tables import SETUPS, paper_tables


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument(
        "--work", type=Path, default=None, help="Folder for scenes and runs (default: a temporary one)."
    )
    parser.add_argument("--backend", default="auto")
    parser.add_argument(
        "--out", default=None, help="JSON file (default: benchmarks/results/paper_tables[-quick].json)."
    )
    args = parser.parse_args()
    start = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        work = args.work or Path(tmp)
        md = paper_tables(work, setup=SETUPS["quick" if args.quick else "full"], backend=args.backend)
        data = json.loads(md.with_suffix(".json").read_text())
        data["markdown"] = md.read_text()
    data["wall_seconds"] = time.perf_counter() - start
    print(data["markdown"])
    record.save("paper_tables", data, tag="quick" if args.quick else "", out=args.out)


def report(r: dict) -> tuple[str, str]:
    names = list(r["scenes"])
    mean = {
        kind: sum(r["scenes"][n]["training"][kind]["miou"] for n in names) / len(names) for kind in ("exact", "hqmask")
    }
    headline = (
        f"mIoU trained on exact masks {mean['exact']:.3f}, on noisy masks after hqmask {mean['hqmask']:.3f} "
        f"({len(names)} scenes, {r['wall_seconds'] / 60:.0f} min)"
    )
    body = re.sub(r"^### (.+)$", r"**\1**", r["markdown"].replace("## Paper tables\n\n", ""), flags=re.M)
    return headline, body


if __name__ == "__main__":
    main()
