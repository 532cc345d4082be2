"""Benchmark: the GPU path as a GPU user runs it, measured end to end on one real capture, and
the ``gsplat`` backend against the ``cpu`` backend on the model it trains.

``prepare`` (here, on the CPU) poses the capture's photos (``sfm``), builds the masks of colour
(``hqmask build``, the demo's options) and carries the people's masks into the undistorted
views: a scene folder small enough to travel to a GPU machine, with the people's masks in
``people_mask/`` (PNG 0/255 per view).

``run`` (on the GPU machine; ``benchmarks/gpu_check.sh`` installs what it needs first):

1. ``gsseg train --backend gsplat`` with the paper's 30k ``gpu`` schedule on the masks of colour:
   train time, peak GPU memory, the Gaussian count, test PSNR / SSIM;
2. the demo's path after training on the same backend: the masks cut at the run's depth jumps,
   ``gsseg segment --smooth 16 --fill-interiors``, one click at the deepest point of the people's
   mask in the first view, scored in the others (mIoU, mAcc);
3. frames per second of the trained model at 1920x1080 (colour over its environment, as the
   viewer draws it), over ``--frames`` frames cycling through the capture's poses;
4. parity of the backends on that model: colour (PSNR of one render against the other on the
   test views) and the 16-d features (largest difference) as trained, where the clamps differ
   (gsplat clamps one Gaussian's alpha at 0.999, 3D-GS at 0.99), and with the opacities below
   0.99, where no clamp acts; the contribution matrices over the training views (relative
   Frobenius difference); the labels each gives (share of Gaussians that agree) and the
   selection of the same click, each backend's region weights and click throughout (IoU of
   the selected Gaussians).

Every stage's result is kept in ``--work`` as it finishes, and from the training on written to
``--out`` too (a command stopped later leaves what it measured), and the training resumes from
its checkpoint, so the same command continues where a stopped one ended; ``--deadline`` seconds
after the start the training stops at a step, writes its checkpoint and the command exits 3
(run it again to go on). Prints and writes JSON.

    python -m benchmarks.gpu_check prepare [--real ../shared/data/real] [--capture statue]
        [--work /tmp/gpu_check_prepare] --out DIR
    python -m benchmarks.gpu_check run --scene DIR [--backend gsplat] [--iters N]
        [--frames 200] [--work /tmp/gpu_check] [--deadline S] [--tag T] [--out FILE]
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch

from benchmarks import record
from benchmarks.real_scenes import interactive, people_masks, posed_scene
from dataset_tools.cameras import PinholeCamera
from dataset_tools.image_files import encode_png, read_mask
from dataset_tools.infra.atomic import write_bytes_atomic
from dataset_tools.infra.interrupts import Interrupted
from dataset_tools.scene import load_scene
from eval.metrics import psnr, ssim
from eval.report import markdown_table
from gsseg.model.environment import background_image
from gsseg.model.gaussians import Gaussians, gaussians_from_points
from gsseg.render import get_backend, render
from gsseg.run.loaded import Run, load_run
from gsseg.segment.clicks import ClickSelector
from gsseg.segment.prompts import click_evidence, deepest_pixel
from gsseg.segment.segment_run import label_gaussians, mask_contributions, mask_regions, segment_run
from gsseg.train.config import TrainConfig
from gsseg.train.trainer import train
from hqmask.build import BuildConfig, build_masks
from pipeline.demo import DEMO_LABELS, DEPTH_MASKS, MASKS, demo_images, masks_at_depth_jumps

PEOPLE = "people_mask"
FPS_SIZE = (1920, 1080)
EXIT_UNFINISHED = 3


def prepare(real: Path, capture: str, work: Path, out: Path) -> Path:
    """A scene folder of ``capture`` at ``out``: its SfM model and the demo's image copy, the
    masks of colour, and the people's masks in the views (``people_mask/``)."""
    scene_dir = posed_scene(real / capture / "photos", work / capture / "scene")
    images = demo_images(scene_dir)
    if not (scene_dir / MASKS).is_dir():
        build_masks(scene_dir, BuildConfig(proposer="graph", associate="tracks", out_masks=MASKS, images=images))
    truth = people_masks(scene_dir, images, real / capture / "masks")
    shutil.rmtree(out, ignore_errors=True)
    out.mkdir(parents=True)
    for name in ("scene.json", "sparse", images, MASKS):
        source = scene_dir / name
        (shutil.copytree if source.is_dir() else shutil.copyfile)(source, out / name)
    (out / PEOPLE).mkdir()
    for view in load_scene(scene_dir, images=images, masks=None).views:
        if view.name in truth:
            write_bytes_atomic(out / PEOPLE / f"{view.stem}.png", encode_png(truth[view.name].astype(np.uint8) * 255))
    return out


class Stages:
    """The results of the stages finished so far, kept in ``work/stages.json`` and handed to
    ``kept`` (all of them) each time one is added."""

    def __init__(self, work: Path, kept: Callable[[dict], None] | None = None):
        self.path = work / "stages.json"
        self.done: dict = json.loads(self.path.read_text()) if self.path.is_file() else {}
        self.kept = kept

    def run(self, name: str, stage) -> dict:
        """The result of ``stage()`` with its seconds, computed once."""
        if name not in self.done:
            start = time.perf_counter()
            self.keep(name, {**stage(), "seconds": time.perf_counter() - start})
            print(f"{name}: {json.dumps(self.done[name])}", flush=True)
        return self.done[name]

    def keep(self, name: str, value) -> None:
        self.done[name] = value
        write_bytes_atomic(self.path, json.dumps(self.done, indent=2).encode())
        if self.kept is not None:
            self.kept(self.done)


def stop_at(deadline: float | None) -> threading.Timer | None:
    """SIGTERM to this process ``deadline`` seconds from now: the training then stops at the end
    of its step and writes a checkpoint."""
    if deadline is None:
        return None
    timer = threading.Timer(max(deadline, 0.0), os.kill, (os.getpid(), signal.SIGTERM))
    timer.daemon = True
    timer.start()
    return timer


def warm_backend(backend: str) -> dict:
    """Compile what ``backend`` needs (gsplat's CUDA extension on its first use) with one tiny
    render."""
    device = get_backend(backend).device
    xyz = np.array([[0.0, 0.0, 2.0], [0.2, 0.0, 2.5]])
    tiny = gaussians_from_points(xyz, np.full((2, 3), 128, np.uint8), initial_opacity=0.5).to(device)
    out = render(tiny, PinholeCamera(16, 16, 16.0, 16.0, 8.0, 8.0), torch.eye(4, device=device)[:3], backend=backend)
    return {"rendered": float(out.rgb.sum())}


def warm_cpu_kernels_aside() -> subprocess.Popen:
    """Compile the ``cpu`` backend's numba kernels into their cache in another process, while
    the GPU trains, so that the parity stage finds them compiled."""
    code = "from gsseg.render import get_backend; from gsseg.train.trainer import warm_up; warm_up(get_backend('cpu'))"
    return subprocess.Popen([sys.executable, "-c", code])


def train_stage(scene: Path, run_dir: Path, backend: str, iters: int | None, deadline: float | None, stages: Stages):
    """The paper's schedule on the masks of colour. At the deadline the training stops at a step
    and writes its checkpoint; the time it ran is kept in ``stages`` under ``train_parts`` and
    Interrupted raised, and the next call resumes."""
    cfg = TrainConfig(schedule="gpu", backend=backend, iters=iters, masks=MASKS, images=demo_images(scene))
    if torch.cuda.is_available():
        torch.cuda.reset_peak_memory_stats()
    parts = stages.done.get("train_parts", [])
    timer = stop_at(deadline)
    start = time.perf_counter()
    try:
        result = train(scene, run_dir, cfg, resume=bool(parts), progress=True)
    except Interrupted:
        stages.keep("train_parts", [*parts, time.perf_counter() - start])
        raise
    finally:
        if timer is not None:
            timer.cancel()
    seconds = sum(parts) + time.perf_counter() - start
    return {
        "iters": cfg.timing.iters,
        "gaussians": result.num_gaussians,
        "train_s": seconds,
        "steps_per_s": result.step / seconds,
        "calls": len(parts) + 1,
        "peak_gpu_mb": torch.cuda.max_memory_allocated() / 2**20 if torch.cuda.is_available() else None,
    }


def test_scores(run: Run, backend: str) -> dict:
    views = run.scene().split("test")
    pairs = [(run.render_rgb(v, backend=backend), v.load_image()) for v in views]
    return {
        "test_views": len(views),
        "test_psnr": float(np.mean([psnr(a, b) for a, b in pairs])),
        "test_ssim": float(np.mean([ssim(a, b) for a, b in pairs])),
    }


def truth_of(scene: Path, images: str) -> dict[str, np.ndarray]:
    """The people's masks by view name."""
    out = {}
    for view in load_scene(scene, images=images, masks=None).views:
        path = scene / PEOPLE / f"{view.stem}.png"
        if path.is_file():
            out[view.name] = read_mask(path) > 127
    return out


def frames_per_second(run: Run, backend: str, frames: int) -> dict:
    """Colour over the environment at 1920x1080 (each view's camera widened to that size, its
    focal length scaled with the width), cycling through the capture's poses."""
    backend = get_backend(backend)
    views = run.scene().views
    g = run.gaussians_on(backend.device)
    width, height = FPS_SIZE

    def frame(k: int) -> torch.Tensor:
        view = views[k % len(views)]
        s = width / view.camera.width
        camera = PinholeCamera(width, height, view.camera.fx * s, view.camera.fy * s, width / 2, height / 2)
        pose = torch.as_tensor(view.cam_from_world, dtype=torch.float32, device=backend.device)
        with torch.no_grad():
            bg = background_image(run.environment, camera, pose)
            return render(
                g, camera, pose, sh_degree=run.config.sh_degree, background=bg, with_features=False, backend=backend
            ).rgb

    for k in range(5):  # warm-up
        frame(k)
    sync = torch.cuda.synchronize if backend.device == "cuda" else (lambda: None)
    sync()
    start = time.perf_counter()
    for k in range(frames):
        frame(k)
    sync()
    seconds = time.perf_counter() - start
    return {"frames": frames, "size": list(FPS_SIZE), "fps": frames / seconds}


def below_clamp(g: Gaussians, limit: float = 0.99) -> Gaussians:
    """The model with every opacity at most ``limit``: no alpha reaches either backend's clamp."""
    logit = torch.logit(torch.tensor(limit, dtype=g.opacity_logits.dtype))
    return Gaussians(**{**g.tensors(), "opacity_logits": g.opacity_logits.clamp_max(logit)})


def render_pair(g: Gaussians, view, backend: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Colour (H, W, 3) and features (H, W, F) of ``g`` on ``backend`` and on ``cpu``, on black."""
    out = []
    for name in (backend, "cpu"):
        device = get_backend(name).device
        pose = torch.as_tensor(view.cam_from_world, dtype=torch.float32, device=device)
        with torch.no_grad():
            r = render(g.to(device), view.camera, pose, backend=name)
        out += [r.rgb.clamp(0, 1).cpu().numpy(), r.features.cpu().numpy()]
    return out[0], out[2], out[1], out[3]


def float_psnr(a: np.ndarray, b: np.ndarray) -> float:
    mse = float(np.mean((a.astype(np.float64) - b) ** 2))
    return float("inf") if mse == 0 else -10 * np.log10(mse)


def parity(run: Run, scene: Path, backend: str, click: tuple[float, float], first_view) -> dict:
    """The backend against ``cpu`` on the run's model (see the module's docstring)."""
    g = run.gaussians.detach()
    test = run.scene().split("test")
    out: dict = {}
    for name, model in (("as_trained", g), ("below_clamp", below_clamp(g))):
        colour, features = [], []
        for view in test:
            rgb_a, rgb_b, feat_a, feat_b = render_pair(model, view, backend)
            colour.append(float_psnr(rgb_a, rgb_b))
            features.append(float(np.abs(feat_a - feat_b).max()))
        out[f"colour_psnr_{name}"] = float(np.mean(colour))
        out[f"colour_psnr_{name}_worst"] = float(np.min(colour))
        out[f"feature_max_error_{name}"] = float(np.max(features))
    contributions = {
        name: mask_contributions(run, scene, masks=DEPTH_MASKS, backend=name, regions=True, progress=False)
        for name in (backend, "cpu")
    }
    a, b = (contributions[name].weights.double() for name in (backend, "cpu"))
    out["contributions_relative_error"] = float((a - b).norm() / b.norm())
    labels, selections = {}, {}
    for name, matrix in contributions.items():
        labels[name] = label_gaussians(run, matrix, DEMO_LABELS).labels
        regions = mask_regions(run, scene, masks=DEPTH_MASKS, backend=name, first=matrix, progress=False)
        seen = click_evidence(g, first_view.camera, first_view.cam_from_world, *click, backend=name)
        selections[name] = ClickSelector(g, labels[name], regions).select([seen])
    out["labels_agree"] = float((labels[backend] == labels["cpu"]).mean())
    sa, sb = selections[backend], selections["cpu"]
    out["selection_iou"] = float((sa & sb).sum() / max((sa | sb).sum(), 1))
    out["selected"] = {name: int(s.sum()) for name, s in selections.items()}
    return out


def run_check(args: argparse.Namespace) -> int:
    start = time.perf_counter()
    deadline = args.deadline
    work, scene, backend = args.work, args.scene, args.backend
    work.mkdir(parents=True, exist_ok=True)

    def results(done: dict) -> dict:
        return {"capture": scene.name, "backend": backend, **{k: v for k, v in done.items() if k != "train_parts"}}

    def save(done: dict) -> None:  # from the training on, each stage's result is in --out at once
        if "train" in done:
            record.save("gpu_check", results(done), tag=args.tag, out=args.out)

    stages = Stages(work, kept=save)
    run_dir = work / "run"
    images = demo_images(scene)
    compiling = warm_cpu_kernels_aside() if "parity" not in stages.done else None
    stages.run("warm_up", lambda: warm_backend(backend))
    try:
        left = None if deadline is None else deadline - (time.perf_counter() - start)
        stages.run("train", lambda: train_stage(scene, run_dir, backend, args.iters, left, stages))
    except Interrupted as stopped:
        print(f"unfinished: {stopped}; run the same command again to continue", flush=True)
        return EXIT_UNFINISHED
    run = load_run(run_dir)
    stages.run("test", lambda: test_scores(run, backend))
    stages.run("fps", lambda: frames_per_second(run, backend, args.frames))

    def depth_masks() -> dict:
        shutil.rmtree(scene / DEPTH_MASKS, ignore_errors=True)
        shutil.rmtree(work / "depth", ignore_errors=True)
        masks_at_depth_jumps(run_dir, scene, images, DEPTH_MASKS, work / "depth", backend=backend, progress=False)
        return {}

    stages.run("depth_masks", depth_masks)

    def segment() -> dict:
        segment_run(run_dir, scene, options=DEMO_LABELS, masks=DEPTH_MASKS, backend=backend, progress=False)
        return {}

    stages.run("segment", segment)
    truth = truth_of(scene, images)
    run = load_run(run_dir)
    views = [v for v in run.scene().views if v.name in truth]
    click = deepest_pixel(truth[views[0].name])
    stages.run("click", lambda: interactive(run, views, truth, max_clicks=1, backend=backend))
    if compiling is not None:
        compiling.wait()
    stages.run("parity", lambda: parity(run, scene, backend, click, views[0]))
    print(json.dumps(results(stages.done), indent=2))
    return 0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    prep = sub.add_parser("prepare", help="Pose a capture and build its masks here, for the GPU machine.")
    prep.add_argument("--real", type=Path, default=Path("../shared/data/real"))
    prep.add_argument("--capture", default="statue")
    prep.add_argument("--work", type=Path, default=Path("/tmp/real_scenes"))
    prep.add_argument("--out", type=Path, required=True)
    check = sub.add_parser("run", help="Train, segment, click, time and compare on the GPU.")
    check.add_argument("--scene", type=Path, required=True, help="A folder `prepare` wrote.")
    check.add_argument("--backend", default="gsplat")
    check.add_argument("--iters", type=int, default=None, help="Training iterations (default: the gpu schedule's).")
    check.add_argument("--frames", type=int, default=200)
    check.add_argument("--work", type=Path, default=Path("/tmp/gpu_check"))
    check.add_argument("--deadline", type=float, default=None, help="Seconds after which the training stops.")
    check.add_argument("--tag", default="")
    check.add_argument("--out", default=None, help="JSON file (default: benchmarks/results/gpu_check.json).")
    args = parser.parse_args()
    if args.command == "prepare":
        print(prepare(args.real, args.capture, args.work, args.out))
        return
    sys.exit(run_check(args))


def report(r: dict) -> tuple[str, str]:
    """The stages that finished; a stage the GPU's time ran out before is "not measured"."""
    missing = "not measured"
    t, test, fps = r["train"], r.get("test"), r.get("fps")
    depth, seg, c, p = r.get("depth_masks"), r.get("segment"), r.get("click"), r.get("parity")
    headline = f"{r['capture']}, {r['backend']}: {t['iters']} steps in {t['train_s'] / 60:.1f} min"
    if test:
        headline += f", test {test['test_psnr']:.2f} dB"
    if fps:
        headline += f", {fps['fps']:.0f} FPS at 1080p"
    if c:
        headline += f", one click mIoU {c['single_click_miou']:.3f}"
    if p:
        headline += (
            f"; parity: colour {p['colour_psnr_below_clamp']:.1f} dB ({p['colour_psnr_as_trained']:.1f} as trained), "
            f"labels {100 * p['labels_agree']:.2f}%, selection IoU {p['selection_iou']:.4f}"
        )
    rows = [
        [
            "training",
            f"{t['iters']} steps in {t['train_s']:.0f} s ({t['steps_per_s']:.1f} steps/s, over {t['calls']} "
            f"calls), {t['gaussians']:,} Gaussians"
            + (f", peak GPU memory {t['peak_gpu_mb']:.0f} MB" if t["peak_gpu_mb"] is not None else ""),
        ],
        [
            "test views",
            f"{test['test_views']}: PSNR {test['test_psnr']:.2f} dB, SSIM {test['test_ssim']:.3f}" if test else missing,
        ],
        ["masks at depth jumps", f"{depth['seconds']:.0f} s" if depth else missing],
        ["segment (labels and region weights)", f"{seg['seconds']:.0f} s" if seg else missing],
        ["one click", f"mIoU {c['single_click_miou']:.3f}, mAcc {c['single_click_macc']:.3f}" if c else missing],
        [
            "frames per second",
            f"{fps['fps']:.1f} at {fps['size'][0]}x{fps['size'][1]} over {fps['frames']} frames" if fps else missing,
        ],
    ]
    if p:
        rows += [
            [
                "colour, gsplat against cpu",
                f"{p['colour_psnr_below_clamp']:.1f} dB below the clamp (worst view "
                f"{p['colour_psnr_below_clamp_worst']:.1f}); {p['colour_psnr_as_trained']:.1f} dB as trained (worst "
                f"{p['colour_psnr_as_trained_worst']:.1f})",
            ],
            [
                "features, largest difference",
                f"{p['feature_max_error_below_clamp']:.2e} below the clamp; "
                f"{p['feature_max_error_as_trained']:.2e} as trained",
            ],
            ["contribution matrices", f"relative difference {p['contributions_relative_error']:.2e}"],
            ["labels", f"{100 * p['labels_agree']:.3f}% of Gaussians agree"],
            ["one-click selection", f"IoU {p['selection_iou']:.4f}"],
        ]
    else:
        rows.append(["parity of the backends", missing])
    note = f" {r['note']}" if "note" in r else ""
    return headline, (
        "The GPU path as the README's commands run it, on one capture (benchmarks/gpu_check.py has the stages; "
        "the SfM model and the masks of colour made on the CPU by `prepare`). Parity on the trained model: "
        "gsplat clamps one Gaussian's alpha at 0.999 where 3D-GS and the cpu backend clamp at 0.99, so "
        f"colour is compared both as trained and with the opacities below 0.99, where no clamp acts.{note}\n\n"
        + markdown_table(["stage", "result"], rows)
    )


if __name__ == "__main__":
    main()
