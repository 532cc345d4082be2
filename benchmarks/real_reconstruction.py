"""Benchmark: reconstruction of real captures. Each capture's photos
(``../shared/data/real/<name>/photos``) go through ``sfm`` and ``gsseg train`` on colour alone
(the image copy ``gsseg demo`` picks, at most 640 px), with the CPU schedule by default or the
paper's (``--schedule gpu --backend gsplat``, on a GPU: the reference of what a capture
allows); the held-out views (every 8th) are
scored by PSNR and SSIM, and the training curve by how much of its best it keeps: the training
PSNR of every tenth of the run with each view's own level taken out (:mod:`eval.training_curve`), at
its peak and at the end (a fit that collapses and never wins its loss back ends far under its
peak). Every stage's wall time is recorded; finished stages
in ``--work`` are reused. ``--demo`` trains what ``gsseg demo`` chooses for each capture
(:func:`pipeline.demo.demo_training`); ``--against FILE`` adds each capture's test PSNR in an
earlier result (the default schedule's) and the gap to it, the worst gap in the headline.
Prints and writes JSON.

    python -m benchmarks.real_reconstruction [--real ../shared/data/real] [--scenes statue,llff_fern]
        [--schedule cpu|gpu] [--backend auto|cpu|gsplat] [--iters N] [--max-gaussians N] [--demo]
        [--against FILE]... [--work /tmp/real_reconstruction] [--out FILE]
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from benchmarks import record
from benchmarks.real_scenes import posed_scene
from dataset_tools.infra.errors import InputError
from eval.metrics import psnr, ssim
from eval.report import markdown_table
from eval.training_curve import curve_summary
from gsseg.render import BACKENDS, get_backend
from gsseg.run.loaded import load_run
from gsseg.train.config import SCHEDULES, TrainConfig
from gsseg.train.trainer import train
from pipeline.demo import demo_images, demo_training
from pipeline.demo_options import DemoOptions


@dataclass(frozen=True)
class Training:
    """The training options this benchmark varies."""

    schedule: str = "cpu"
    backend: str = "auto"
    iters: int | None = None
    max_gaussians: int | None = None
    demo: bool = False  # the iterations and cap gsseg demo chooses for the capture

    @property
    def run_name(self) -> str:
        """The run folder's name: its schedule (when not the CPU's), length and cap."""
        schedule = "" if self.schedule == "cpu" else f"{self.schedule}_"
        return f"run_{schedule}{self.iters or 'default'}_{self.max_gaussians or 'default'}"


def run_scene(name: str, real: Path, work: Path, training: Training) -> dict:
    out = work / name
    start = time.perf_counter()
    try:
        scene_dir = posed_scene(real / name / "photos", out / "scene")
    except InputError as refused:  # the capture cannot be posed: a row that says so
        return {"scene": name, "refused": str(refused), "sfm_s": time.perf_counter() - start}
    sfm_s = time.perf_counter() - start
    images = demo_images(scene_dir)
    if training.demo:
        plan = demo_training(scene_dir, images, DemoOptions(scene=scene_dir))
        training = replace(training, iters=plan.iters, max_gaussians=plan.max_gaussians)
    start = time.perf_counter()
    run_dir = out / training.run_name
    if not (run_dir / "gaussians.ply").is_file():
        cfg = TrainConfig(
            schedule=training.schedule,
            backend=training.backend,
            iters=training.iters,
            masks=None,
            images=images,
            max_gaussians=training.max_gaussians,
        )
        train(scene_dir, run_dir, cfg)
    train_s = time.perf_counter() - start
    run = load_run(run_dir)
    scene = run.scene()
    views = scene.split("test")
    renders = [run.render_rgb(v) for v in views]
    truth = [v.load_image() for v in views]
    history = run.folder.read_history()
    return {
        "scene": name,
        "images": images,
        "size": [views[0].camera.width, views[0].camera.height],
        "views": len(scene.views),
        "test_views": len(views),
        "schedule": run.config.schedule,
        "backend": get_backend(run.config.backend).name,
        "iters": run.config.timing.iters,
        "gaussians": len(run.gaussians),
        "test_psnr": float(np.mean([psnr(a, b) for a, b in zip(renders, truth)])),
        "test_ssim": float(np.mean([ssim(a, b) for a, b in zip(renders, truth)])),
        **curve_summary(history, len(run.record.train_views), run.config.seed),
        "curve": "view levels",
        "sfm_s": sfm_s,
        "train_s": train_s,
    }


def earlier_psnr(files: list[Path]) -> dict[str, dict]:
    """Each capture's test PSNR, iterations, training seconds and source file in earlier
    results of this benchmark (a later file's capture replaces an earlier one's)."""
    found = {}
    for path in files:
        for x in json.loads(path.read_text())["results"]["scenes"]:
            found[x["scene"]] = {k: x[k] for k in ("test_psnr", "iters", "train_s")} | {"file": path.name}
    return found


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--real", type=Path, default=Path("../shared/data/real"))
    parser.add_argument("--scenes", default="statue,llff_fern")
    parser.add_argument("--schedule", choices=tuple(SCHEDULES), default="cpu")
    parser.add_argument("--backend", choices=("auto", *BACKENDS), default="auto", help="Rasterizer.")
    parser.add_argument("--iters", type=int, default=None, help="Training iterations (default: the schedule's).")
    parser.add_argument("--max-gaussians", type=int, default=None)
    parser.add_argument("--demo", action="store_true", help="Train what gsseg demo chooses for each capture.")
    parser.add_argument(
        "--against",
        type=Path,
        action="append",
        default=[],
        help="An earlier result of this benchmark (the default schedule's) to compare each capture's test PSNR with.",
    )
    parser.add_argument("--work", type=Path, default=Path("/tmp/real_reconstruction"))
    parser.add_argument("--tag", default="", help="Suffix of the JSON file's name.")
    parser.add_argument("--out", default=None, help="JSON file (default: benchmarks/results/real_reconstruction.json).")
    args = parser.parse_args()
    training = Training(args.schedule, args.backend, args.iters, args.max_gaussians, args.demo)
    against = earlier_psnr(args.against)
    results = {"scenes": []}
    for name in args.scenes.split(","):
        results["scenes"].append(run_scene(name, args.real, args.work, training))
        if name in against and "refused" not in results["scenes"][-1]:
            results["scenes"][-1]["against"] = against[name]
        print(json.dumps(results["scenes"][-1], indent=2))
    record.save("real_reconstruction", results, tag=args.tag, out=args.out)


def report(r: dict) -> tuple[str, str]:
    refused = [x for x in r["scenes"] if "refused" in x]
    posed = [x for x in r["scenes"] if "refused" not in x]
    headline = "; ".join(
        [f"{x['scene']}: test {x['test_psnr']:.2f} dB, curve ends {x['kept']:+.2f} dB from its peak" for x in posed]
        + [f"{x['scene']}: not posed by sfm" for x in refused]
    )
    compared = [x for x in posed if "against" in x]
    if compared:
        worst = max(compared, key=lambda x: x["against"]["test_psnr"] - x["test_psnr"])
        gap = worst["against"]["test_psnr"] - worst["test_psnr"]
        headline = f"worst gap to the earlier result: {worst['scene']} {gap:.2f} dB; {headline}"
    rows = [
        [
            x["scene"],
            f"{x['size'][0]}x{x['size'][1]}",
            str(x["views"]),
            f"{x.get('schedule', 'cpu')} {x['iters']}",
            f"{x['gaussians']:,}",
            f"{x['test_psnr']:.2f}",
            f"{x['test_ssim']:.3f}",
            f"{x['peak_psnr']:.2f} at {x['peak_step']} / {x['final_psnr']:.2f}",
            f"{x['sfm_s']:.0f} / {x['train_s']:.0f}",
            *(_against_cells(x) if compared else []),
        ]
        for x in posed
    ]
    table = markdown_table(
        [
            "scene",
            "size",
            "views",
            "schedule, iterations",
            "Gaussians",
            "test PSNR",
            "test SSIM",
            "training PSNR: peak / end",
            "seconds: sfm / train",
            *(["earlier: iterations, test PSNR, train s", "gap"] if compared else []),
        ],
        rows,
    )
    curve = (
        "the training PSNR of every tenth of the run with each view's own level taken out (eval/training_curve.py)"
        if all(x.get("curve") == "view levels" for x in posed)
        else "the training PSNR averaged over 100 steps"
    )
    note = f" {r['note']}" if "note" in r else ""
    not_posed = "".join(f"\n\n{x['scene']}: not posed: {x['refused']}" for x in refused)
    return headline, (
        f"Colour alone, held-out views every 8th; {curve}. A stage reused from an earlier run shows "
        f"about 0 s.{note}\n\n" + table + not_posed
    )


def _against_cells(x: dict) -> list[str]:
    """The earlier result's cells of a capture's row (its iterations, PSNR and training time;
    the gap to it), blank where it has none."""
    if "against" not in x:
        return ["", ""]
    a = x["against"]
    earlier = f"{a['iters']}, {a['test_psnr']:.2f}, {a['train_s']:.0f} ({a['file']})"
    return [earlier, f"{a['test_psnr'] - x['test_psnr']:.2f}"]


if __name__ == "__main__":
    main()
