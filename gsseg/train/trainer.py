"""The training loop: photometric + object loss, densification, checkpoints, resume."""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from dataset_tools.errors import InputError
from dataset_tools.scene import Scene, View, load_scene
from gsseg.environment import Environment, background_image, mean_up, profile_bins
from gsseg.gaussians import gaussians_from_points, random_points
from gsseg.ply import write_ply
from gsseg.render import RenderOutput, backend_device, render, resolve_backend
from gsseg.run_folder import (CHECKPOINTS, CLASSIFIER, CONFIG, ENVIRONMENT, GAUSSIANS, METRICS, make_classifier,
                              write_json, write_torch)
from gsseg.train.config import TrainConfig
from gsseg.train.densify import DensifyOptions, DensifyStats, densify_and_prune
from gsseg.train.losses import object_loss, photometric_loss, psnr
from gsseg.train.optim import GaussianOptimizer
from gsseg.train.views import TrainView, camera_extent, load_views

LOG_EVERY = 10


class TrainingDiverged(InputError):
    """The loss or the parameters stopped being finite."""


@dataclass
class TrainResult:
    run: Path
    step: int
    num_gaussians: int
    seconds: float
    finished: bool


def _view_at(step: int, n_views: int, seed: int) -> int:
    """The view trained at 1-based ``step``: epochs of seeded permutations, so that the order
    depends on the step alone and a resumed run sees the same views."""
    epoch, k = divmod(step - 1, n_views)
    return int(np.random.default_rng([seed, epoch]).permutation(n_views)[k])


def _means_lr(step: int, cfg: TrainConfig, iters: int, extent: float) -> float:
    """3D-GS's log-linear decay of the position learning rate over the run."""
    t = min(max(step / iters, 0.0), 1.0)
    return extent * math.exp((1 - t) * math.log(cfg.lr.means) + t * math.log(cfg.lr.means_final))


def _initial_gaussians(scene: Scene, cfg: TrainConfig):
    """Gaussians at the SfM points, or at random points within the cameras' bounds when there are none."""
    if len(scene.points):
        xyz, rgb = scene.points.xyz, scene.points.rgb
    else:
        centers = np.stack([v.center for v in scene.views])
        xyz, rgb = random_points(centers.mean(0), camera_extent(scene.views), cfg.random_init_points, cfg.seed)
    return gaussians_from_points(xyz, rgb, initial_opacity=cfg.initial_opacity, seed=cfg.seed)


def _latest_checkpoint(run: Path) -> Path | None:
    found = sorted((run / CHECKPOINTS).glob("step_*.pt"))
    return found[-1] if found else None


def _prepare_run_folder(run: Path, cfg: TrainConfig, resume: bool) -> TrainConfig:
    """Check the folder and return the config to use: the saved one when resuming (with
    ``iters`` taken from ``cfg`` if it changes)."""
    config_path = run / CONFIG
    if resume:
        if not config_path.is_file() or _latest_checkpoint(run) is None:
            raise InputError(f"{run} holds no checkpoint to resume; start it without --resume.")
        saved = TrainConfig.from_json(json.loads(config_path.read_text()))
        return saved if cfg.iters in (None, saved.iters) else TrainConfig.from_json(
            {**saved.to_json(), "iters": cfg.iters})
    if config_path.exists():
        raise InputError(f"{run} already holds a run; continue it with --resume or choose another --out.")
    run.mkdir(parents=True, exist_ok=True)
    return cfg


def train(scene_dir: Path | str, run: Path | str, cfg: TrainConfig, *, resume: bool = False,
          stop_after: int | None = None, progress: bool = True) -> TrainResult:
    """Train 3D-GS with object features on a scene folder and write the run folder.

    Args:
        scene_dir: the scene (COLMAP model, images, optional masks).
        run: the output run folder.
        cfg: the options; with ``resume`` those saved in the run are used (``iters`` may change).
        resume: continue from the latest checkpoint of ``run``.
        stop_after: write a checkpoint and stop at this step (continue later with ``resume``).
        progress: show a progress bar.

    Raises:
        TrainingDiverged: the loss became NaN or infinite; the last good checkpoint is kept.
    """
    run = Path(run)
    cfg = _prepare_run_folder(run, cfg, resume)
    timing = cfg.timing
    backend = resolve_backend(cfg.backend)
    device = backend_device(backend)
    scene = load_scene(scene_dir, images=cfg.images, masks=cfg.masks)
    train_views = scene.split("train") or scene.views
    extent = camera_extent(scene.views)
    views = load_views(train_views, progress=progress, device=device)
    write_json(run / CONFIG, {**cfg.to_json(), "scene": str(Path(scene_dir).resolve()), "backend_used": backend,
                              "extent": extent, "near_plane": scene.views[0].camera.near,
                              "train_views": [v.name for v in views]})

    torch.manual_seed(cfg.seed)
    opt = GaussianOptimizer(_initial_gaussians(scene, cfg).to(device), cfg.lr, extent)
    classifier = make_classifier(cfg.num_classes).to(device)
    environment = _environment(cfg, train_views)
    environment = environment.to(device) if environment is not None else None
    # The classifier and the environment: small modules beside the Gaussians, one Adam.
    groups = [{"params": list(classifier.parameters()), "lr": cfg.lr.classifier}]
    if environment is not None:
        groups.append({"params": list(environment.parameters()), "lr": cfg.lr.environment})
    cls_opt = torch.optim.Adam(groups, eps=1e-15)
    stats = DensifyStats.zeros(len(opt), device)
    history: list[dict] = []
    step = 0
    if resume:
        ckpt = torch.load(_latest_checkpoint(run), map_location=device, weights_only=False)
        opt.load_state_dict(ckpt["gaussians"])
        classifier.load_state_dict(ckpt["classifier"])
        if environment is not None:
            environment.load_state_dict(ckpt["environment"])
        cls_opt.load_state_dict(ckpt["classifier_adam"])
        stats = DensifyStats(**ckpt["densify"])
        history, step = ckpt["history"], ckpt["step"]

    def save_checkpoint() -> None:
        write_torch(run / CHECKPOINTS / f"step_{step:07d}.pt", {
            "step": step, "gaussians": opt.state_dict(), "classifier": classifier.state_dict(),
            "environment": environment.state_dict() if environment is not None else None,
            "classifier_adam": cls_opt.state_dict(), "densify": vars(stats), "history": history})
        for old in sorted((run / CHECKPOINTS).glob("step_*.pt"))[:-2]:
            old.unlink()

    densify = DensifyOptions(cfg.densify_grad_threshold, cfg.percent_dense, cfg.prune_opacity, extent,
                             timing.max_gaussians)
    last = min(timing.iters, stop_after) if stop_after is not None else timing.iters
    start_time = time.perf_counter()
    bar = tqdm(total=timing.iters, initial=step, desc="training", unit="it", disable=not progress,
               dynamic_ncols=True)
    try:
        while step < last:
            step += 1
            opt.set_lr("means", _means_lr(step, cfg, timing.iters, extent))
            view = views[_view_at(step, len(views), cfg.seed)]
            losses, out = _train_step(opt, classifier, environment, view, cfg, backend,
                                      sh_degree=min(cfg.sh_degree, step // timing.sh_increase_every),
                                      obj_pixels=timing.object_loss_pixels,
                                      generator=torch.Generator(device).manual_seed(cfg.seed * 7919 + step))
            if not math.isfinite(losses["loss"]):
                kept = _latest_checkpoint(run)
                raise TrainingDiverged(
                    f"training diverged at step {step} (loss {losses['loss']}); "
                    + (f"the last good checkpoint is {kept}; " if kept else "no checkpoint was written yet; ")
                    + "lower the learning rates and --resume, or start again.")
            if step < timing.densify_until and out.means2d.grad is not None:
                with torch.no_grad():
                    stats.update(out.means2d.grad, out.radii, view.camera.width, view.camera.height)
            opt.step()
            cls_opt.step()
            cls_opt.zero_grad(set_to_none=True)
            if timing.densify_from < step < timing.densify_until and step % timing.densify_every == 0:
                gen = torch.Generator(device).manual_seed(cfg.seed * 1_000_003 + step)
                densify_and_prune(opt, stats, densify, step > timing.opacity_reset_every, gen)
            if step < timing.densify_until and step % timing.opacity_reset_every == 0:
                opacities = torch.clamp_max(opt.gaussians.opacities.detach(), 0.01)
                opt.reset("opacity_logits", torch.logit(opacities))
            if step % LOG_EVERY == 0 or step == timing.iters:
                history.append({"step": step, **losses, "gaussians": len(opt)})
                bar.set_postfix(loss=f"{losses['loss']:.4f}", psnr=f"{losses['psnr']:.2f}", n=len(opt))
            bar.update(1)
            if step % timing.checkpoint_every == 0 or step == last:
                save_checkpoint()
    except KeyboardInterrupt:
        bar.close()
        save_checkpoint()
        raise
    bar.close()
    finished = step >= timing.iters
    if finished:
        write_ply(opt.gaussians.detach().to("cpu"), run / GAUSSIANS)
        write_torch(run / CLASSIFIER, {k: v.cpu() for k, v in classifier.state_dict().items()})
        if environment is not None:
            write_torch(run / ENVIRONMENT, {k: v.cpu() for k, v in environment.state_dict().items()})
        write_json(run / METRICS, {"train": {"steps": step, "gaussians": len(opt), "history": history}})
    return TrainResult(run=run, step=step, num_gaussians=len(opt),
                       seconds=time.perf_counter() - start_time, finished=finished)


def _environment(cfg: TrainConfig, views: list[View]) -> Environment | None:
    """The untrained background of ``cfg``: None (black), SH only, or SH plus an elevation
    profile about the cameras' mean up with bins a pixel apart at the finest camera."""
    if cfg.environment_degree is None:
        return None
    if not cfg.environment_profile:
        return Environment(cfg.environment_degree)
    return Environment(cfg.environment_degree, up=mean_up([v.cam_from_world for v in views]),
                       bins=profile_bins(max(max(v.camera.fx, v.camera.fy) for v in views)))


def _train_step(opt: GaussianOptimizer, classifier: torch.nn.Linear, environment: Environment | None,
                view: TrainView, cfg: TrainConfig, backend: str, sh_degree: int, obj_pixels: int = 0,
                generator: torch.Generator | None = None) -> tuple[dict, RenderOutput]:
    """Render one view, compute the loss and back-propagate it (unless it is not finite).
    Returns the loss terms and the render."""
    use_mask = view.mask is not None and cfg.gamma_obj != 0
    out = render(opt.gaussians, view.camera, view.cam_from_world, sh_degree=sh_degree,
                 background=background_image(environment, view.camera, view.cam_from_world),
                 with_features=use_mask, backend=backend)
    rgb_loss = photometric_loss(out.rgb, view.image, cfg.lambda_dssim)
    obj = object_loss(out.features, view.mask, classifier, obj_pixels, generator) if use_mask else torch.zeros((), device=rgb_loss.device)
    loss = rgb_loss + cfg.gamma_obj * obj
    if torch.isfinite(loss):
        loss.backward()
    return {"loss": loss.item(), "rgb": rgb_loss.item(), "obj": obj.item(), "psnr": psnr(out.rgb, view.image)}, out
