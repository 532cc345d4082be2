"""Benchmark: what ``gsseg view`` does per interaction on a trained, segmented run: a frame
for a training camera (and with segments coloured), a click selection, relabelling from the
cached contribution matrix, and computing that matrix when no cache exists; and whether a
click through the browser's camera picks the object `gsseg edit --click` picks on the same
pixel, for every object of a training view. Prints and writes JSON.

    python -m benchmarks.viewer_speed --run demo/run [--max-size 640] [--out viewer_speed.json]
"""

from __future__ import annotations

import argparse
import json
import math
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import torch
from scipy import ndimage
from scipy.spatial.transform import Rotation

from benchmarks import record
from dataset_tools.infra.errors import InputError
from eval.report import markdown_table
from gsseg.render.pixel_labels import segment_pixels
from gsseg.run.folder import RunFolder, read_edit_record
from gsseg.run.loaded import load_run
from gsseg.viewer.session import ViewCamera, ViewerSession, browser_camera


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
        RunFolder(run).contributions.unlink(missing_ok=True)
        session = ViewerSession(load_run(run))
        view = session.scene.split("train")[0]
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
        agree, clicks = clicks_agree(run, fresh, view)
        return {
            "clicks_agree": agree,
            "clicks": clicks,
            "run": str(run_dir),
            "gaussians": len(session.run.gaussians),
            "size": [camera.width, camera.height],
            "backend": session.backend.name,
            "frame_s": frame,
            "segments_frame_s": segments,
            "select_s": select,
            "relabel_s": relabel,
            "relabel_new_viewer_s": cached,
            "contributions_uncached_s": uncached,
            "train_views": len(session.scene.split("train")),
        }


def clicks_agree(run: Path, session: ViewerSession, view) -> tuple[int, int]:
    """For the pixel deepest inside each object of ``view``'s own labels (rendered segments):
    (clicks where the viewer and `gsseg edit --click` pick the same object, clicks)."""
    world_from_cam = view.cam_from_world[:3, :3].T
    browser = browser_camera(
        Rotation.from_matrix(world_from_cam).as_quat(scalar_first=True),
        -world_from_cam @ view.cam_from_world[:3, 3],
        2 * math.atan(view.camera.height / 2 / view.camera.fy),
        view.camera.width,
        view.camera.height,
        max_size=max(view.camera.width, view.camera.height),
        near=view.camera.near,
    )
    session.show_segments = False
    labels = _rendered_labels(session, view)
    agree = clicks = 0
    for label in (int(x) for x in np.unique(labels) if x):
        depth = ndimage.distance_transform_edt(labels == label)
        if depth.max() < 3:
            continue
        row, col = np.unravel_index(depth.argmax(), depth.shape)
        u, v = col + 0.5, row + 0.5
        try:
            mine = session.select_at(browser, u, v)
        except InputError:
            mine = None
        name = f"click_{label}"
        done = subprocess.run(
            [
                str(Path(sys.executable).parent / "gsseg"),
                "edit",
                str(run),
                "--click",
                view.stem,
                str(u),
                str(v),
                "--op",
                "extract",
                "--name",
                name,
            ],
            capture_output=True,
            text=True,
        )
        theirs = read_edit_record(RunFolder(run).edit(name))["object_id"] if done.returncode == 0 else None
        agree += mine == theirs
        clicks += 1
    return agree, clicks


def _rendered_labels(session: ViewerSession, view) -> np.ndarray:
    """(H, W) the label whose Gaussians weigh most at each pixel."""
    pose = torch.as_tensor(view.cam_from_world, dtype=torch.float32)
    return segment_pixels(
        session.run.gaussians, session.segmentation.labels, view.camera, pose, backend=session.backend
    )


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
    headline = (
        f"clicks agree with gsseg edit --click {r['clicks_agree']}/{r['clicks']}; relabel from the cache "
        f"{r['relabel_s']:.2f} s ({r['relabel_new_viewer_s']:.2f} s in a new viewer), "
        f"frame {r['frame_s']:.2f} s at {r['size'][0]}x{r['size'][1]}, click {r['select_s']:.2f} s"
    )
    rows = [
        ["frame for a training camera", f"{r['frame_s']:.3f} s"],
        ["frame, segments coloured", f"{r['segments_frame_s']:.3f} s"],
        ["click selection (depth render + 20-nearest mode)", f"{r['select_s']:.3f} s"],
        ["re-run reassignment, matrix in memory", f"{r['relabel_s']:.3f} s"],
        [
            "re-run reassignment in a new viewer (matrix read from contributions.npz)",
            f"{r['relabel_new_viewer_s']:.3f} s",
        ],
        [f"contribution matrix without a cache ({r['train_views']} views)", f"{r['contributions_uncached_s']:.2f} s"],
    ]
    intro = (
        f"`{r['run']}`: {r['gaussians']:,} Gaussians, frames at {r['size'][0]}x{r['size'][1]} on the "
        f"`{r['backend']}` backend, best of 3.\n\n"
    )
    return headline, intro + markdown_table(["what", "seconds"], rows)


if __name__ == "__main__":
    main()
