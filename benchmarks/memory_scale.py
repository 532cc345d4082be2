"""Benchmark: training memory and step time against the number of views, with the views kept
in memory (uint8) and read from disk a few steps ahead. Captures of 50, 200 and 400 views at
1920x1080 are made once in --work (an orbit ray-cast at low resolution and enlarged: image
content does not change what is measured); each capture trains --steps steps in a fresh
process per mode, which reports its peak RSS and seconds a step. Prints and writes JSON.

    python -m benchmarks.memory_scale [--views 50,200,400] [--size 1920x1080] [--steps 300]
                                      [--work /tmp/gsseg-memory-scale] [--out memory_scale.json]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np

from benchmarks import record
from dataset_tools import colmap
from dataset_tools.image_files import write_png
from dataset_tools.infra.atomic import atomic_directory
from dataset_tools.scene import load_scene
from dataset_tools.synth import SynthConfig, generate_scene
from eval.report import markdown_table

MODES = ("memory", "disk")
TRAIN = """
import json, resource, sys
from gsseg.train.config import TrainConfig
from gsseg.train.trainer import train
scene, run, steps, mode = sys.argv[1:]
result = train(scene, run, TrainConfig(iters=int(steps), backend="cpu"), cache_views=mode, progress=False)
print(json.dumps({"seconds_per_step": result.seconds / result.step, "gaussians": result.num_gaussians,
                  "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
"""


def capture(work: Path, views: int, width: int, height: int) -> Path:
    """An orbit of ``views`` views at ``width`` x ``height`` (made once: reused when present)."""
    out = work / f"orbit_{views}_{width}x{height}"
    if out.is_dir():
        return out
    small = generate_scene(
        SynthConfig(views=views, res=height // 6, objects=6, supersample=1, points_per_view=20),
        work / f"small_{views}",
        overwrite=True,
        progress=False,
    )
    scene = load_scene(small.root)
    with atomic_directory(out) as tmp:
        cameras = []
        for v in scene.views:
            image = cv2.resize(v.load_image(), (width, height), interpolation=cv2.INTER_LINEAR)
            mask = cv2.resize(v.load_mask(), (width, height), interpolation=cv2.INTER_NEAREST)
            write_png(tmp / "images" / v.name, image)
            write_png(tmp / "object_mask" / f"{v.stem}.png", mask)
            cameras.append(v.camera.resized(width, height))
        scale = np.array([width / scene.views[0].camera.width, height / scene.views[0].camera.height])
        colmap.write_model(
            tmp / "sparse" / "0",
            [v.name for v in scene.views],
            cameras,
            [v.cam_from_world for v in scene.views],
            [(v.point_ids, v.uv * scale) for v in scene.views],
            scene.points.xyz,
            scene.points.rgb,
        )
        (tmp / "scene.json").write_bytes((small.root / "scene.json").read_bytes())
    return out


def trained(scene: Path, run: Path, steps: int, mode: str) -> dict:
    """Peak RSS and seconds a step of ``steps`` training steps in a fresh process."""
    done = subprocess.run(
        [sys.executable, "-c", TRAIN, str(scene), str(run), str(steps), mode],
        capture_output=True,
        text=True,
        check=True,
    )
    return json.loads(done.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--views", default="50,200,400")
    parser.add_argument("--size", default="1920x1080")
    parser.add_argument("--steps", type=int, default=300)
    parser.add_argument("--work", type=Path, default=Path("/tmp/gsseg-memory-scale"))
    parser.add_argument("--out", default=None, help="JSON file (default: benchmarks/results/memory_scale.json).")
    args = parser.parse_args()
    width, height = (int(x) for x in args.size.split("x"))
    args.work.mkdir(parents=True, exist_ok=True)
    rows = []
    for n in (int(x) for x in args.views.split(",")):
        scene = capture(args.work, n, width, height)
        train_views = len(load_scene(scene).split("train"))
        for mode in MODES:
            run = args.work / f"run_{n}_{mode}"
            subprocess.run(["rm", "-rf", str(run)], check=True)
            rows.append({"views": n, "train_views": train_views, "mode": mode, **trained(scene, run, args.steps, mode)})
            print(json.dumps(rows[-1]))
    view_mb = 4 * width * height / 2**20
    out = {
        "size": [width, height],
        "steps": args.steps,
        "view_uint8_mb": view_mb,
        "view_float_mb": 20 * width * height / 2**20,
        "rows": rows,
        **slopes(rows),
    }
    print(json.dumps(out, indent=2))
    record.save("memory_scale", out, out=args.out)


def slopes(rows: list[dict]) -> dict:
    """Per mode: peak RSS growth per training view (least squares) and the step time of disk
    against memory at the largest capture."""
    out = {}
    for mode in MODES:
        mine = [r for r in rows if r["mode"] == mode]
        if len(mine) > 1:
            out[f"{mode}_mb_per_view"] = float(
                np.polyfit([r["train_views"] for r in mine], [r["peak_rss_mb"] for r in mine], 1)[0]
            )
    largest = max(r["views"] for r in rows)
    by_mode = {r["mode"]: r for r in rows if r["views"] == largest}
    out["disk_over_memory_step"] = by_mode["disk"]["seconds_per_step"] / by_mode["memory"]["seconds_per_step"]
    out["disk_peak_rss_mb_largest"] = by_mode["disk"]["peak_rss_mb"]
    return out


def report(r: dict) -> tuple[str, str]:
    headline = (
        f"{r['size'][0]}x{r['size'][1]}: memory mode +{r.get('memory_mb_per_view', float('nan')):.1f} MiB a "
        f"view ({r['view_uint8_mb']:.1f} MiB of uint8 pixels); disk mode peak "
        f"{r['disk_peak_rss_mb_largest'] / 1024:.2f} GiB at {max(x['views'] for x in r['rows'])} views, "
        f"step {r['disk_over_memory_step']:.2f}x memory's"
    )
    table = markdown_table(
        ["views", "mode", "peak RSS, MiB", "s a step", "Gaussians"],
        [
            [
                f"{x['views']} ({x['train_views']} train)",
                x["mode"],
                f"{x['peak_rss_mb']:.0f}",
                f"{x['seconds_per_step']:.2f}",
                f"{x['gaussians']:,}",
            ]
            for x in r["rows"]
        ],
    )
    return headline, (
        f"{r['steps']} training steps per run on the cpu backend, each run in a fresh process. A view "
        f"held as float32 colour and int64 IDs took {r['view_float_mb']:.1f} MiB; as uint8 it takes "
        f"{r['view_uint8_mb']:.1f} MiB; growth a view is the least-squares slope of peak RSS over the "
        f"training views.\n\n{table}"
    )


if __name__ == "__main__":
    main()
