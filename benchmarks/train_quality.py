"""Benchmark: train on a synthetic orbit scene (256x256, 24 views, LLFF hold-out) with the
CPU default schedule and score the test views: PSNR of the renders and mIoU of the rendered
label argmax against the exact masks. Optionally the beer capture (images at 1/4 size, no
masks: PSNR only), and gsplat beside cpu where a GPU is present (also on the paper's 30k GPU
schedule with ``--gpu-schedule``). Prints and writes JSON.

    python -m benchmarks.train_quality [--out train_quality.json] [--beer ../shared/data/beer]
        [--backends cpu,gsplat] [--gpu-schedule] [--train-seeds 0,1,2] [--no-environment-profile]

Held-out PSNR moves by a few tenths of a dB between training runs that differ only in their
seed or in the last bits of their numerics; ``--train-seeds`` trains the orbit scene once
per seed and reports the mean and the spread.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

from dataset_tools.image_files import read_image, read_mask
from dataset_tools.scene import load_scene
from dataset_tools.synth import SynthConfig, generate_scene
from eval.metrics import mean_iou, psnr
from gsseg.render.gsplat_blend import gsplat_available
from gsseg.render_views import render_run
from gsseg.train import TrainConfig, train


def train_and_score(scene: Path, work: Path, cfg: TrainConfig, name: str) -> dict:
    """Train ``cfg`` on ``scene`` and score its test views."""
    start = time.perf_counter()
    result = train(scene, work / f"run_{name}", cfg)
    seconds = time.perf_counter() - start
    what = ("rgb", "labels") if cfg.masks else ("rgb",)
    renders = render_run(result.run, scene, work / f"test_{name}", split="test", what=what,
                         backend=cfg.backend, progress=False)
    views = load_scene(scene, images=cfg.images, masks=cfg.masks).split("test")
    out = {"train_seconds": seconds, "iterations": result.step, "gaussians": result.num_gaussians,
           "test_views": len(views),
           "test_psnr": sum(psnr(read_image(renders / "rgb" / f"{v.stem}.png"), v.load_image()) for v in views) / len(views)}
    if "labels" in what and all(v.mask_path for v in views):
        out["test_miou"] = mean_iou([read_mask(renders / "labels" / f"{v.stem}.png") for v in views],
                                    [v.load_mask() for v in views])
    print(name, json.dumps(out))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="train_quality.json")
    parser.add_argument("--iters", type=int, default=None, help="Override the schedule's length.")
    parser.add_argument("--beer", type=Path, default=None, help="Also train the beer capture found here.")
    parser.add_argument("--backends", default=None,
                        help="Comma-separated backends to train with (default: cpu, and gsplat where it can run).")
    parser.add_argument("--gpu-schedule", action="store_true",
                        help="Also train the orbit scene with gsplat on the paper's 30k-iteration schedule.")
    parser.add_argument("--train-seeds", default="0", help="Comma-separated training seeds for the orbit scene.")
    parser.add_argument("--no-environment-profile", dest="profile", action="store_false",
                        help="Train without the environment's elevation profile (SH only).")
    args = parser.parse_args()
    train_seeds = [int(x) for x in args.train_seeds.split(",")]
    backends = args.backends.split(",") if args.backends else ["cpu"] + (["gsplat"] if gsplat_available() else [])

    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        synth = generate_scene(SynthConfig(views=24, res=256, path="orbit", seed=0), work / "orbit").root
        for backend in backends:
            runs = []
            for seed in train_seeds:
                name = f"orbit_{backend}" + (f"_seed{seed}" if seed else "")
                cfg = TrainConfig(iters=args.iters, backend=backend, seed=seed, environment_profile=args.profile)
                runs.append(results.setdefault(name, train_and_score(synth, work, cfg, name)))
            if len(runs) > 1:
                results[f"orbit_{backend}_over_seeds"] = {
                    f"{key}_{stat}": fn([r[key] for r in runs]) for key in ("test_psnr", "test_miou", "train_seconds")
                    for stat, fn in (("mean", lambda xs: sum(xs) / len(xs)), ("min", min), ("max", max))}
        if args.gpu_schedule:
            cfg = TrainConfig(schedule="gpu", backend="gsplat", environment_profile=args.profile)
            results["orbit_gsplat_gpu_schedule"] = train_and_score(synth, work, cfg, "orbit_gsplat_gpu_schedule")
        if args.beer:
            for backend in backends:
                results[f"beer_{backend}"] = train_and_score(
                    args.beer, work, TrainConfig(iters=args.iters, backend=backend, images="images_4", masks=None,
                                             environment_profile=args.profile),
                    f"beer_{backend}")
    print(json.dumps(results, indent=2))
    Path(args.out).write_text(json.dumps(results, indent=2) + "\n")


if __name__ == "__main__":
    main()
