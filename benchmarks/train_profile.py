"""Benchmark: where the time of ``gsseg demo``'s training goes on a real capture. The capture's
photos (``../shared/data/real/<name>/photos``) go through ``sfm`` and the demo's first mask
pass; then the demo's training (its steps for the capture, at most 30k Gaussians, object
features on the masks) runs under cProfile, and the time of the training loop is split into the phases of a
step: the rasterizer (the projection's and the blend's forward and backward passes), the rest of
the forward pass and of the backward pass, the losses, the optimiser, densification and the
loop around the steps. Prints and writes JSON.

    python -m benchmarks.train_profile [--real ../shared/data/real] [--scene statue]
        [--iters N] [--max-gaussians 30000] [--work /tmp/train_profile] [--out FILE]

cProfile counts wall time per Python function; the numba kernels and torch's operators run
inside the functions that call them, so the phases hold them. Its own cost is a few
microseconds a Python call, a small share of steps of tenths of a second.
"""

from __future__ import annotations

import argparse
import cProfile
import json
import pstats
import shutil
from pathlib import Path

from benchmarks import record
from benchmarks.real_scenes import posed_scene
from eval.report import markdown_table
from gsseg.train.config import TrainConfig
from gsseg.train.trainer import train
from hqmask.build import BuildConfig, build_masks
from pipeline.demo import MASKS, demo_images, demo_training
from pipeline.demo_options import DemoOptions

# (file path suffix, function name) of the functions whose cumulative time the phases are made of
FUNCTIONS = {
    "loop": ("gsseg/train/trainer.py", "_loop"),
    "step": ("gsseg/train/trainer.py", "_train_step"),
    "loss_and_backward": ("gsseg/train/trainer.py", "_loss_and_backward"),
    "render": ("gsseg/render/__init__.py", "render"),
    "projection": ("gsseg/render/cpu_projection.py", "project_gaussians_cpu"),
    "projection_backward": ("gsseg/render/cpu_projection.py", "backward"),
    "blend_forward": ("gsseg/render/cpu_blend.py", "forward"),
    "blend_backward": ("gsseg/render/cpu_blend.py", "backward"),
    "background": ("gsseg/model/environment.py", "background_image"),
    "photometric_loss": ("gsseg/train/losses.py", "photometric_loss"),
    "object_loss": ("gsseg/train/losses.py", "object_loss"),
    "psnr": ("gsseg/train/losses.py", "psnr"),
    "backward": ("torch/_tensor.py", "backward"),
    "densify_statistics": ("gsseg/train/strategy.py", "after_backward"),
    "densify": ("gsseg/train/strategy.py", "after_step"),
}


def cumulative_seconds(stats: pstats.Stats) -> dict[str, float]:
    """The cumulative wall seconds of each of :data:`FUNCTIONS` (0 for one never called)."""
    out = dict.fromkeys(FUNCTIONS, 0.0)
    for (filename, _, name), (_, _, _, cumulative, _) in stats.stats.items():
        for key, (suffix, function) in FUNCTIONS.items():
            if name == function and filename.replace("\\", "/").endswith(suffix):
                out[key] += cumulative
    return out


def phases(s: dict[str, float]) -> dict[str, float]:
    """Disjoint phases of the training loop, in seconds, from :func:`cumulative_seconds`."""
    rasterizer = s["projection"] + s["projection_backward"] + s["blend_forward"] + s["blend_backward"]
    losses = s["photometric_loss"] + s["object_loss"] + s["psnr"]
    densify = s["densify_statistics"] + s["densify"]
    return {
        "rasterizer": rasterizer,
        "projection": s["projection"],
        "projection backward": s["projection_backward"],
        "blend forward": s["blend_forward"],
        "blend backward": s["blend_backward"],
        "rest of the forward pass (SH colours, features)": s["render"] - s["projection"] - s["blend_forward"],
        "environment": s["background"],
        "losses": losses,
        "rest of the backward pass (SH, environment, losses, autograd)": s["backward"]
        - s["blend_backward"]
        - s["projection_backward"],
        "densification": densify,
        "optimisers": s["step"] - s["loss_and_backward"] - densify,
        "around the steps (views, logging, checkpoints)": s["loop"] - s["step"],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--real", type=Path, default=Path("../shared/data/real"))
    parser.add_argument("--scene", default="statue")
    parser.add_argument("--iters", type=int, default=None, help="Steps (default: the demo's for the capture).")
    parser.add_argument("--max-gaussians", type=int, default=None, help="Cap (default: the demo's for the capture).")
    parser.add_argument("--work", type=Path, default=Path("/tmp/train_profile"))
    parser.add_argument("--tag", default="", help="Suffix of the JSON file's name.")
    parser.add_argument("--out", default=None, help="JSON file (default: benchmarks/results/train_profile.json).")
    args = parser.parse_args()

    scene_dir = posed_scene(args.real / args.scene / "photos", args.work / args.scene / "scene")
    images = demo_images(scene_dir)
    if not (scene_dir / MASKS).is_dir():
        build_masks(scene_dir, BuildConfig(proposer="graph", associate="tracks", out_masks=MASKS, images=images))
    run_dir = args.work / args.scene / "run"
    shutil.rmtree(run_dir, ignore_errors=True)
    options = DemoOptions(scene=scene_dir, iters=args.iters, max_gaussians=args.max_gaussians)
    plan = demo_training(scene_dir, images, options)
    cfg = TrainConfig(iters=plan.iters, masks=MASKS, images=images, max_gaussians=plan.max_gaussians)
    profiler = cProfile.Profile()
    profiler.enable()
    result = train(scene_dir, run_dir, cfg, progress=False)
    profiler.disable()
    seconds = cumulative_seconds(pstats.Stats(profiler))
    results = {
        "scene": args.scene,
        "images": images,
        "iters": result.step,
        "gaussians": result.num_gaussians,
        "loop_s": seconds["loop"],
        "steps_per_s": result.step / seconds["loop"],
        "phases_s": phases(seconds),
    }
    print(json.dumps(results, indent=2))
    record.save("train_profile", results, tag=args.tag, out=args.out)


def report(r: dict) -> tuple[str, str]:
    loop = r["loop_s"]
    headline = (
        f"{r['scene']}, the demo's training: {r['steps_per_s']:.2f} steps/s; rasterizer "
        f"{r['phases_s']['rasterizer'] / loop:.0%} of the loop"
    )
    rows = [[name, f"{s:.1f}", f"{s / loop:.1%}"] for name, s in r["phases_s"].items()]
    table = markdown_table(["phase", "seconds", "share of the loop"], rows)
    return headline, (
        f"{r['scene']} ({r['images']}), {r['iters']} steps, {r['gaussians']:,} Gaussians at the end; the "
        f"training loop took {loop:.0f} s. The rasterizer's rows below it (projection and its backward, "
        "blend forward, blend backward) are its parts.\n\n" + table
    )


if __name__ == "__main__":
    main()
