"""Benchmark: what ``gsseg view`` does per interaction on a trained, segmented run: a frame
for a training camera (and with segments coloured), a click selection, relabelling from the
cached contribution matrix, and computing that matrix when no cache exists. Prints and writes
JSON.

    python -m benchmarks.viewer_speed --run demo/run [--max-size 640] [--out viewer_speed.json]
"""

from __future__ import annotations

import argparse
import json
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks import record
from gsseg.run import load_run
from gsseg.viewer.session import ViewCamera, ViewerSession


def timed(fn, repeats: int = 3) -> float:
    best = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - start)
    return best


def measure(run_dir: Path, max_size: int) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        run = Path(shutil.copytree(run_dir, Path(tmp) / "run"))  # the cache is written into the copy
        (run / "contributions.npz").unlink(missing_ok=True)
        session = ViewerSession(load_run(run))
        view = session.run.scene().split("train")[0]
        scale = min(1.0, max_size / max(view.camera.width, view.camera.height))
        camera = view.camera.resized(round(view.camera.width * scale), round(view.camera.height * scale))
        at = ViewCamera(camera, view.cam_from_world)
        start = time.perf_counter()
        session.contributions()
        uncached = time.perf_counter() - start
        frame = timed(lambda: session.frame(at))
        session.show_segments = True
        segments = timed(lambda: session.frame(at))
        select = timed(lambda: session.select_at(at, camera.width / 2, camera.height / 2))
        relabel = timed(lambda: session.relabel("prior", 0.5))
        fresh = ViewerSession(load_run(run))  # a new viewer on the same run reads the cache
        start = time.perf_counter()
        fresh.relabel("prior", 0.5)
        cached = time.perf_counter() - start
        assert np.array_equal(fresh.segmentation.labels, session.segmentation.labels)
        return {"run": str(run_dir), "gaussians": len(session.run.gaussians), "size": [camera.width, camera.height],
                "backend": session.backend.name, "frame_s": frame, "segments_frame_s": segments, "select_s": select,
                "relabel_s": relabel, "relabel_new_viewer_s": cached, "contributions_uncached_s": uncached,
                "train_views": len(session.run.scene().split("train"))}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--run", type=Path, default=Path("demo/run"), help="A segmented run (default: the demo's).")
    parser.add_argument("--max-size", type=int, default=640)
    parser.add_argument("--out", default=None, help="JSON file (default: benchmarks/results/viewer_speed.json).")
    args = parser.parse_args()
    out = measure(args.run, args.max_size)
    print(json.dumps(out, indent=2))
    record.save("viewer_speed", out, out=args.out)


def report(r: dict) -> tuple[str, str]:
    headline = (f"relabel from the cache {r['relabel_s']:.2f} s ({r['relabel_new_viewer_s']:.2f} s in a new viewer), "
                f"frame {r['frame_s']:.2f} s at {r['size'][0]}x{r['size'][1]}, click {r['select_s']:.2f} s")
    rows = [("frame for a training camera", f"{r['frame_s']:.3f} s"),
            ("frame, segments coloured", f"{r['segments_frame_s']:.3f} s"),
            ("click selection (depth render + 20-nearest mode)", f"{r['select_s']:.3f} s"),
            ("re-run reassignment, matrix in memory", f"{r['relabel_s']:.3f} s"),
            ("re-run reassignment in a new viewer (matrix read from contributions.npz)",
             f"{r['relabel_new_viewer_s']:.3f} s"),
            (f"contribution matrix without a cache ({r['train_views']} views)",
             f"{r['contributions_uncached_s']:.2f} s")]
    intro = (f"`{r['run']}`: {r['gaussians']:,} Gaussians, frames at {r['size'][0]}x{r['size'][1]} on the "
             f"`{r['backend']}` backend, best of 3.\n\n")
    return headline, intro + "\n".join(["| what | seconds |", "| --- | --- |"] + [f"| {x} | {y} |" for x, y in rows])


if __name__ == "__main__":
    main()
