"""Benchmark: train on a synthetic orbit scene (256x256, 24 views, LLFF hold-out) with the
CPU default schedule and score the test views: PSNR and SSIM of the renders and mIoU of the
rendered label argmax against the exact masks. Optionally the beer capture (images at 1/4
size, no masks: image scores only), and gsplat beside cpu where a GPU is present (also on
the paper's 30k GPU schedule with ``--gpu-schedule``). With ``--coupled`` each orbit run is
also trained with ``--geometry-from-masks`` beside it (the object loss also shaping the
geometry). Prints and writes JSON.

    python -m benchmarks.train_quality [--beer ../shared/data/beer] [--backends cpu,gsplat]
        [--gpu-schedule] [--train-seeds 0,1,2] [--no-environment-profile] [--opacity-reg W] [--coupled] [--iters N]
        [--out FILE]

Held-out PSNR moves by a few tenths of a dB between training runs that differ only in their
seed or in the last bits of their numerics; ``--train-seeds`` trains the orbit scene once
per seed and reports the mean and the spread.
"""

from __future__ import annotations

import argparse
import json
import tempfile
from dataclasses import replace
from pathlib import Path

from benchmarks import record
from dataset_tools.scene import GT_MASKS
from eval.report import markdown_table
from gsseg.render import BACKENDS
from gsseg.run.folder import RunFolder
from gsseg.train.config import TrainConfig
from pipeline.experiment import SceneSpec, synthetic_scene, test_view_scores, train_run


def train_and_score(scene: Path, run: Path, cfg: TrainConfig) -> dict:
    """Train ``cfg`` on ``scene`` and score its test views."""
    seconds = train_run(scene, run, cfg, progress=True)
    metrics = json.loads(RunFolder(run).metrics.read_text())["train"]
    out = {
        "train_seconds": seconds,
        "iterations": metrics["steps"],
        "gaussians": metrics["gaussians"],
        **test_view_scores(run, scene, backend=cfg.backend),
    }
    print(run.name, json.dumps(out))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=None, help="JSON file (default: benchmarks/results/train_quality.json).")
    parser.add_argument("--iters", type=int, default=None, help="Override the schedule's length.")
    parser.add_argument("--beer", type=Path, default=None, help="Also train the beer capture found here.")
    parser.add_argument(
        "--backends",
        default=None,
        help="Comma-separated backends to train with (default: cpu, and gsplat where it can run).",
    )
    parser.add_argument(
        "--gpu-schedule",
        action="store_true",
        help="Also train the orbit scene with gsplat on the paper's 30k-iteration schedule.",
    )
    parser.add_argument("--train-seeds", default="0", help="Comma-separated training seeds for the orbit scene.")
    parser.add_argument(
        "--no-environment-profile",
        dest="profile",
        action="store_false",
        help="Train without the environment's elevation profile (SH only).",
    )
    parser.add_argument(
        "--environment-smoothing",
        type=float,
        default=TrainConfig.environment_smoothing,
        help="Weight of the elevation profile's total variation.",
    )
    parser.add_argument(
        "--opacity-reg", type=float, default=TrainConfig.opacity_reg, help="Weight of the mean opacity in the loss."
    )
    parser.add_argument(
        "--coupled", action="store_true", help="Also train each orbit run with the object loss shaping the geometry."
    )
    parser.add_argument("--tag", default="", help="Suffix of the default JSON file name.")
    args = parser.parse_args()
    train_seeds = [int(x) for x in args.train_seeds.split(",")]
    backends = (
        args.backends.split(",") if args.backends else ["cpu"] + (["gsplat"] if BACKENDS["gsplat"].available() else [])
    )

    options = {
        "environment_profile": args.profile,
        "environment_smoothing": args.environment_smoothing,
        "opacity_reg": args.opacity_reg,
    }
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        synth = synthetic_scene(work / "orbit", SceneSpec(path="orbit", seed=0, res=256, views=24))
        for backend in backends:
            runs = []
            for seed in train_seeds:
                name = f"orbit_{backend}" + (f"_seed{seed}" if seed else "")
                cfg = TrainConfig(iters=args.iters, masks=GT_MASKS, backend=backend, seed=seed, **options)
                runs.append(results.setdefault(name, train_and_score(synth, work / name, cfg)))
                if args.coupled:
                    coupled = replace(cfg, geometry_from_masks=True)
                    results[f"{name}_coupled"] = train_and_score(synth, work / f"{name}_coupled", coupled)
            if len(runs) > 1:
                results[f"orbit_{backend}_over_seeds"] = {
                    f"{key}_{stat}": fn([r[key] for r in runs])
                    for key in ("test_psnr", "test_miou", "train_seconds")
                    for stat, fn in (("mean", lambda xs: sum(xs) / len(xs)), ("min", min), ("max", max))
                }
        if args.gpu_schedule:
            cfg = TrainConfig(schedule="gpu", masks=GT_MASKS, backend="gsplat", **options)
            results["orbit_gsplat_gpu_schedule"] = train_and_score(synth, work / "orbit_gpu", cfg)
        if args.beer:
            for backend in backends:
                cfg = TrainConfig(iters=args.iters, backend=backend, images="images_4", masks=None, **options)
                results[f"beer_{backend}"] = train_and_score(args.beer, work / f"beer_{backend}", cfg)
    results = {"runs": results, "setup": {k: str(v) if isinstance(v, Path) else v for k, v in vars(args).items()}}
    print(report(results)[1])
    record.save("train_quality", results, tag=args.tag, out=args.out)


def report(r: dict) -> tuple[str, str]:
    runs = {k: v for k, v in r["runs"].items() if not k.endswith("_over_seeds")}
    seeds = [k for k in runs if k.startswith("orbit_cpu") and not k.endswith("_coupled")]
    orbit = [runs[k] for k in seeds]
    headline = ", ".join(
        f"{k}: {v['test_psnr']:.2f} dB"
        + (f", mIoU {v['test_miou']:.3f}" if "test_miou" in v else "")
        + (f", {v['train_seconds']:.0f} s" if v["train_seconds"] else "")
        for k, v in runs.items()
    )
    if len(orbit) > 1:
        headline = (
            f"orbit cpu over {len(orbit)} seeds: {min(v['test_psnr'] for v in orbit):.2f}-"
            f"{max(v['test_psnr'] for v in orbit):.2f} dB; "
            + ", ".join(f"{k}: {v['test_psnr']:.2f} dB" for k, v in runs.items() if k not in seeds)
        )
    rows = [
        [
            k,
            str(v["iterations"]),
            str(v["gaussians"]),
            f"{v['test_psnr']:.2f}",
            f"{v['test_ssim']:.3f}",
            f"{v['test_miou']:.3f}" if "test_miou" in v else "n/a",
            f"{v['train_seconds']:.0f}" if v["train_seconds"] else "reused",
        ]
        for k, v in runs.items()
    ]
    table = markdown_table(
        ["run", "iterations", "Gaussians", "test PSNR (dB)", "test SSIM", "test mIoU", "seconds"], rows
    )
    profile = "with" if r["setup"]["profile"] else "without"
    return headline, (
        f"Orbit: 24 views at 256², 3 LLFF test views, {profile} the environment's elevation profile; "
        f"beer: 71 views at 1/4 size, 9 test views, no masks.\n\n{table}"
    )


if __name__ == "__main__":
    main()
