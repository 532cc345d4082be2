"""The training loop: photometric + object loss, densification, checkpoints, resume.

A run folder goes through three states: new (nothing, or a config.json without any
checkpoint: a start that never got far, which a new start replaces), in progress
(checkpoints) and finished (the model files). Checkpoints hold the state at the end of a
step; Ctrl-C and SIGTERM stop after the step in progress and write one, so that
``--resume`` continues exactly where the run stopped.
"""

from __future__ import annotations

import contextlib
import math
import shutil
import subprocess
import sys
import time
import warnings
from collections.abc import Collection
from dataclasses import dataclass, fields, replace
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from dataset_tools.cameras import PinholeCamera
from dataset_tools.fingerprint import scene_fingerprint
from dataset_tools.infra.atomic import first_missing, require_folder_path
from dataset_tools.infra.errors import InputError, OptionError, RunFailed
from dataset_tools.infra.interrupts import Interrupted, stop_requests
from dataset_tools.infra.locks import shared_folder
from dataset_tools.infra.overlap import refuse_overlap, scene_entries
from dataset_tools.scene import Scene, View, load_scene
from gsseg.model.environment import Environment, background_image, mean_up, profile_bins
from gsseg.model.environment_cpu import ENVIRONMENT_KERNELS
from gsseg.model.gaussians import Gaussians, gaussians_from_points, make_classifier, random_points
from gsseg.model.sh_cpu import SH_KERNELS, eval_sh_cpu
from gsseg.render import Backend, RenderOutput, get_backend, render
from gsseg.render.cpu_kernels import STEP_KERNELS, compiled_on_disk
from gsseg.render.cpu_projection import PROJECTION_KERNELS
from gsseg.run.folder import RunFolder, write_torch
from gsseg.run.record import RunRecord, scene_difference
from gsseg.train.config import TrainConfig
from gsseg.train.losses import knn_identity_loss, object_loss, photometric_loss, psnr_from_mse, sample_pixels
from gsseg.train.optim import GaussianOptimizer
from gsseg.train.ssim_cpu import SSIM_KERNELS, mean_ssim_cpu
from gsseg.train.strategy import DensifyOptions, DensifyStrategy
from gsseg.train.views import TrainView, TrainViews, camera_extent

LOG_EVERY = 10
KEEP_CHECKPOINTS = 2
CHECKPOINT_KEYS = frozenset(("step", "gaussians", "classifier", "environment", "classifier_adam", "densify", "history"))


class TrainingDiverged(RunFailed):
    """The loss stopped being finite at ``step`` (``loss``); ``checkpoint`` is the last good
    one, None when none was written yet."""

    def __init__(self, step: int, loss: float, checkpoint: Path | None):
        self.step, self.loss, self.checkpoint = step, loss, checkpoint
        kept = f"the last good checkpoint is {checkpoint}" if checkpoint else "no checkpoint was written yet"
        super().__init__(
            f"training diverged at step {step} (loss {loss}); {kept}; lower the learning rates and "
            "resume, or start again."
        )


@dataclass
class TrainResult:
    run: Path
    step: int
    num_gaussians: int
    seconds: float
    finished: bool


@dataclass
class _State:
    """Everything a checkpoint holds: the step reached and what was learned up to it."""

    step: int
    gaussians: GaussianOptimizer
    classifier: torch.nn.Linear
    environment: Environment | None
    small_adam: torch.optim.Adam  # the classifier's and the environment's parameters
    strategy: DensifyStrategy
    history: list[dict]

    def state_dict(self) -> dict:
        """Everything a checkpoint holds, under :data:`CHECKPOINT_KEYS`."""
        return {
            "step": self.step,
            "gaussians": self.gaussians.state_dict(),
            "classifier": self.classifier.state_dict(),
            "environment": self.environment.state_dict() if self.environment is not None else None,
            "classifier_adam": self.small_adam.state_dict(),
            "densify": self.strategy.state_dict(),
            "history": self.history,
        }

    def load_state_dict(self, ckpt: dict) -> None:
        self.gaussians.load_state_dict(ckpt["gaussians"])
        self.classifier.load_state_dict(ckpt["classifier"])
        if self.environment is not None:
            self.environment.load_state_dict(ckpt["environment"])
        self.small_adam.load_state_dict(ckpt["classifier_adam"])
        self.strategy.load_state_dict(ckpt["densify"])
        self.history, self.step = ckpt["history"], ckpt["step"]


def view_at_step(step: int, n_views: int, seed: int) -> int:
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


def _environment(cfg: TrainConfig, views: list[View]) -> Environment | None:
    """The untrained background of ``cfg``: None (black), SH only, or SH plus an elevation
    profile about the cameras' mean up with bins a pixel apart at the finest camera."""
    if cfg.environment_degree is None:
        return None
    if not cfg.environment_profile:
        return Environment(cfg.environment_degree)
    return Environment(
        cfg.environment_degree,
        up=mean_up([v.cam_from_world for v in views]),
        bins=profile_bins(max(max(v.camera.fx, v.camera.fy) for v in views)),
    )


def _saved_config(folder: RunFolder) -> TrainConfig:
    """The options recorded in a run's config.json, refused in one sentence when damaged."""
    return folder.read_config().config


def _asked_options(cfg: TrainConfig, given: Collection[str] | None) -> set[str]:
    """The options a resume was asked for: ``given``, or those of ``cfg`` that are not the
    defaults."""
    if given is not None:
        return set(given)
    default = TrainConfig()
    return {f.name for f in fields(TrainConfig) if getattr(cfg, f.name) != getattr(default, f.name)}


def _resumed_config(saved: TrainConfig, cfg: TrainConfig, asked: set[str], folder: RunFolder) -> TrainConfig:
    """The saved options, refusing any asked option that differs from them; ``iters`` may only
    grow (the schedule then stretches to it)."""
    for name in sorted(asked - {"iters"}):
        if getattr(cfg, name) != getattr(saved, name):
            raise OptionError(
                f"the run was trained with {{{name}}}, not {getattr(cfg, name)!r}; leave the option out to "
                "resume, or start a new run elsewhere.",
                file=folder.config,
                **{name: getattr(saved, name)},
            )
    if "iters" not in asked or cfg.iters is None or cfg.iters == saved.timing.iters:
        return saved
    if cfg.iters < saved.timing.iters:
        raise InputError(
            f"{folder.config}: the run was trained towards {saved.timing.iters} iterations; a resume may "
            f"only lengthen it, not shorten it to {cfg.iters}."
        )
    return replace(saved, iters=cfg.iters)


def _settled_config(
    folder: RunFolder, cfg: TrainConfig, resume: bool, given: Collection[str] | None
) -> tuple[TrainConfig, bool]:
    """The config to train with and whether to resume: the saved one when resuming (where
    :func:`_resumed_config` allows), which needs a checkpoint. A folder whose start never
    reached a checkpoint is started afresh without ``resume``."""
    started = folder.config.is_file()
    has_checkpoint = bool(folder.checkpoint_files())
    if resume:
        if not has_checkpoint:
            found = (
                "a finished model but no checkpoints"
                if folder.finished
                else ("a config.json but no checkpoint" if started else "no run")
            )
            raise OptionError(
                f"holds {found} to resume; start it without {{resume}} in a new folder.", file=folder.root, resume=True
            )
        return _resumed_config(_saved_config(folder), cfg, _asked_options(cfg, given), folder), True
    if started and (has_checkpoint or folder.finished):
        raise OptionError(
            "already holds a run; continue it with {resume} or choose another folder.", file=folder.root, resume=True
        )
    return cfg, False


def _latest_good_checkpoint(folder: RunFolder, device: str) -> dict:
    """The newest checkpoint that loads and holds every part of a training state
    (:meth:`_State.state_dict`); a damaged newest one falls back to the one before (with a
    warning), and none that loads is one error naming the newest."""
    skipped: list[tuple[Path, Exception]] = []
    for path in folder.checkpoint_files()[::-1]:
        try:
            ckpt = torch.load(path, map_location=device, weights_only=True)
            missing = sorted(CHECKPOINT_KEYS - set(ckpt)) if isinstance(ckpt, dict) else ["everything"]
            if missing:
                raise KeyError(f"no {', '.join(missing)}")
        except Exception as e:  # a truncated, foreign or partial file: torch raises several types
            skipped.append((path, e))
            continue
        for damaged_path, e in skipped:
            warnings.warn(
                f"{damaged_path}: damaged checkpoint ({type(e).__name__}); resuming from {path.name}.", stacklevel=2
            )
        return ckpt
    if not skipped:
        raise InputError(f"{folder.checkpoints}: no checkpoint to resume from; start the run again in a new folder.")
    path, e = skipped[0]
    raise InputError(
        f"{path}: damaged checkpoint ({type(e).__name__}: {e}), and no older one loads; start the run again in a "
        "new folder."
    ) from None


def _new_state(scene: Scene, cfg: TrainConfig, train_views: list[View], extent: float, device: str) -> _State:
    timing = cfg.timing
    torch.manual_seed(cfg.seed)
    gaussians = GaussianOptimizer(_initial_gaussians(scene, cfg).to(device), cfg.lr, extent)
    classifier = make_classifier(cfg.num_classes).to(device)
    environment = _environment(cfg, train_views)
    environment = environment.to(device) if environment is not None else None
    groups = [{"params": list(classifier.parameters()), "lr": cfg.lr.classifier}]
    if environment is not None:
        groups.append({"params": list(environment.parameters()), "lr": cfg.lr.environment})
    strategy = DensifyStrategy(
        timing,
        DensifyOptions(cfg.densify_grad_threshold, cfg.percent_dense, cfg.prune_opacity, extent, timing.max_gaussians),
        cfg.seed,
    )
    strategy.start(len(gaussians), device)
    return _State(0, gaussians, classifier, environment, torch.optim.Adam(groups, eps=1e-15), strategy, [])


def _save_checkpoint(folder: RunFolder, state: _State) -> Path:
    path = folder.checkpoint(state.step)
    write_torch(path, state.state_dict())
    for old in folder.checkpoint_files()[:-KEEP_CHECKPOINTS]:
        old.unlink()
    return path


def _export(folder: RunFolder, state: _State) -> None:
    """Write the finished model: gaussians.ply, classifier.pt, environment.pt, metrics.json."""
    folder.write_model(state.gaussians.gaussians, state.classifier, state.environment, state.step, state.history)


def _train_step(state: _State, view: TrainView, cfg: TrainConfig, backend: Backend, step: int) -> dict:
    """Train ``step`` on ``view``: render, loss, backward, densification statistics, optimiser
    steps and densification. Returns the loss terms; the state is unchanged if the loss is not
    finite."""
    timing = cfg.timing
    state.gaussians.set_lr("means", _means_lr(step, cfg, timing.iters, state.strategy.options.extent))
    generator = torch.Generator(backend.device).manual_seed(cfg.seed * 7919 + step)
    losses, out = _loss_and_backward(
        state,
        view,
        cfg,
        backend,
        min(cfg.sh_degree, step // timing.sh_increase_every),
        timing.object_loss_pixels,
        generator,
    )
    if not math.isfinite(losses["loss"]):
        return losses
    state.strategy.after_backward(step, out, view.camera.width, view.camera.height)
    state.gaussians.step()
    state.small_adam.step()
    state.small_adam.zero_grad(set_to_none=True)
    state.strategy.after_step(step, state.gaussians)
    return losses


def _loss_and_backward(
    state: _State,
    view: TrainView,
    cfg: TrainConfig,
    backend: Backend,
    sh_degree: int,
    obj_pixels: int,
    generator: torch.Generator,
) -> tuple[dict, RenderOutput]:
    """Render one view, compute the loss and back-propagate it (unless it is not finite). The
    object loss sees ``obj_pixels`` pixels drawn at random (0: every pixel), whose features
    alone are rendered where the backend can."""
    use_mask = view.mask is not None and cfg.gamma_obj != 0
    labels = view.mask.reshape(-1) if use_mask else None
    pixels = sample_pixels(len(labels), obj_pixels, generator, labels.device) if use_mask else None
    out = render(
        state.gaussians.gaussians,
        view.camera,
        view.cam_from_world,
        sh_degree=sh_degree,
        background=background_image(state.environment, view.camera, view.cam_from_world),
        with_features=use_mask,
        feature_geometry_grad=cfg.geometry_from_masks,
        feature_pixels=pixels,
        backend=backend,
    )
    rgb_loss = photometric_loss(out.rgb, view.image, cfg.lambda_dssim)
    if use_mask:
        obj = object_loss(out.features, labels if pixels is None else labels[pixels], state.classifier)
    else:
        obj = torch.zeros((), device=rgb_loss.device)
    loss = rgb_loss + cfg.gamma_obj * obj
    if cfg.opacity_reg > 0:
        loss = loss + cfg.opacity_reg * state.gaussians.gaussians.opacities.mean()
    if cfg.environment_smoothing > 0 and state.environment is not None:
        loss = loss + cfg.environment_smoothing * state.environment.profile_variation()
    if cfg.knn_reg > 0:
        g = state.gaussians.gaussians
        loss = loss + cfg.knn_reg * knn_identity_loss(
            g.means, g.obj_feat, state.classifier, cfg.knn_samples, cfg.knn_k, generator
        )
    mse = torch.mean((out.rgb.detach().clamp(0, 1) - view.image) ** 2)
    # One transfer of the step's numbers: on a GPU each .item() waits for the device.
    total, rgb, obj_value, mse_value = torch.stack([loss.detach(), rgb_loss.detach(), obj.detach(), mse]).tolist()
    if math.isfinite(total):
        loss.backward()
    return {"loss": total, "rgb": rgb, "obj": obj_value, "psnr": psnr_from_mse(mse_value)}, out


def train(
    scene_dir: Path | str,
    run: Path | str,
    cfg: TrainConfig,
    *,
    resume: bool = False,
    given: Collection[str] | None = None,
    stop_after: int | None = None,
    other_scene: bool = False,
    cache_views: str = "auto",
    progress: bool = True,
) -> TrainResult:
    """Train 3D-GS with object features on a scene folder and write the run folder.

    Args:
        scene_dir: the scene (COLMAP model, images, optional masks).
        run: the output run folder.
        cfg: the options; with ``resume`` those saved in the run are used.
        resume: continue from the latest checkpoint of ``run``; an option of ``cfg`` that was
            asked for and differs from the saved one is refused (``iters`` may only grow).
        given: the names of the options of ``cfg`` that were asked for (a command line's);
            None: those that differ from :class:`TrainConfig`'s defaults.
        stop_after: write a checkpoint and stop at this step (continue later with ``resume``).
        other_scene: let ``resume`` continue on another scene than the run's.
        cache_views: ``memory``, ``disk`` or ``auto``: where the views wait between the steps
            that use them (:class:`gsseg.train.views.TrainViews`); the result is the same.
        progress: show a progress bar.

    Raises:
        TrainingDiverged: the loss became NaN or infinite; the last good checkpoint is kept.
        Interrupted: Ctrl-C or SIGTERM; a checkpoint of the last finished step was written.
    """
    folder = RunFolder(run)
    if stop_after is not None and stop_after < 1:
        raise OptionError("{stop_after}: give a step of 1 or more.", stop_after=stop_after)
    require_folder_path(folder.root)
    refuse_overlap(folder.root, scene_entries(scene_dir))
    created = first_missing(folder.root)
    try:
        with folder.lock():
            cfg, restore = _settled_config(folder, cfg, resume, given)
            # The scene's masks may not change while it trains (read view by view with --cache-views disk).
            masks_read = cfg.masks is not None and Path(scene_dir).is_dir()
            with shared_folder(Path(scene_dir), "masks") if masks_read else contextlib.nullcontext():
                return _train_locked(
                    folder, Path(scene_dir), cfg, restore, stop_after, other_scene, cache_views, progress
                )
    except BaseException:
        if created is not None and not folder.config.exists():  # a start that wrote nothing leaves nothing
            shutil.rmtree(created, ignore_errors=True)
        raise


def _train_locked(
    folder: RunFolder,
    scene_dir: Path,
    cfg: TrainConfig,
    restore: bool,
    stop_after: int | None,
    other_scene: bool,
    cache_views: str,
    progress: bool,
) -> TrainResult:
    backend = get_backend(cfg.backend)
    scene = load_scene(scene_dir, images=cfg.images, masks=cfg.masks)
    if cfg.masks is not None and scene.mask_dir is None:
        raise OptionError(
            "mask folder not found; build masks with `hqmask build` or train on colour alone with {masks}.",
            file=scene_dir / cfg.masks,
            masks=None,
        )
    if restore and not other_scene:
        difference = scene_difference(folder.read_config(), scene)
        if difference is not None:
            raise OptionError(
                f"not the scene {folder.root} was trained on ({difference}); pass that scene, or "
                "{other_scene} to continue on this one.",
                file=scene_dir,
                other_scene=True,
            )
    train_views = scene.split("train")
    if not train_views:
        raise InputError(
            f"{scene_dir}: every view is a test view, none is left to train on; list fewer views "
            "under split.test in scene.json."
        )
    extent = camera_extent(scene.views)
    views = TrainViews(
        train_views,
        lambda step: view_at_step(step, len(train_views), cfg.seed),
        mode=cache_views,
        device=backend.device,
        progress=progress,
    )
    try:
        state = _new_state(scene, cfg, train_views, extent, backend.device)
        if restore:
            try:
                state.load_state_dict(_latest_good_checkpoint(folder, backend.device))
            except (KeyError, ValueError, TypeError, RuntimeError, AttributeError) as e:
                raise InputError(
                    f"{folder.checkpoints}: the newest checkpoint does not hold this run's training state "
                    f"({type(e).__name__}); start the run again in a new folder."
                ) from None
        folder.write_config(
            RunRecord(
                cfg,
                str(scene_dir.resolve()),
                backend.name,
                extent,
                scene.views[0].camera.near,
                views.names,
                scene_fingerprint(scene),
            )
        )
        return _loop(folder, state, views, cfg, backend, stop_after, progress)
    finally:
        views.close()


def warm_up(backend: Backend, progress: bool = False) -> None:
    """Load the CPU kernels from numba's cache, compiling them first where the cache lacks them,
    before the progress bar starts (saying so on the first run), so that the bar's estimate
    times training steps alone.

    A kernel compiled in this process and the same kernel loaded from the cache round
    differently (up to 1e-6 in a render, measured on the blending): a machine's first run would
    not repeat. So a cache that lacks them is filled by other processes, and this one loads
    them from it, as every later run does: one runs :func:`tiny_step`, another compiles the
    kernels that do not need a render (:func:`tiny_parts`) beside it, which the first then
    loads where they are ready."""
    if backend.name != "cpu":
        return
    kernels = STEP_KERNELS + PROJECTION_KERNELS + SH_KERNELS + SSIM_KERNELS + ENVIRONMENT_KERNELS
    if not compiled_on_disk(kernels):
        if progress:
            tqdm.write("compiling the CPU kernels (first run only, about a minute)", file=sys.stderr)
        children = [
            subprocess.Popen([sys.executable, "-c", f"from gsseg.train.trainer import {step}; {step}()"])
            for step in ("tiny_parts", "tiny_step")
        ]
        try:
            for child in children:
                child.wait()
        finally:  # interrupted: no compiler left running (numba writes each cache file whole)
            for child in children:
                child.kill()
    tiny_step()


def tiny_parts() -> None:
    """SSIM, the environment and SH colours with their backward passes, called as a training
    step calls them, without a render: the kernels of a step that the projection and the
    blending do not need, in the order :func:`tiny_step` reaches them last."""
    image = torch.rand(16, 16, 3, requires_grad=True)
    mean_ssim_cpu(image, torch.zeros_like(image)).backward()
    _, _, background = _tiny_view()
    background.sum().backward()
    sh = torch.rand(4, 16, 3, requires_grad=True)
    directions = torch.nn.functional.normalize(torch.rand(4, 3), dim=-1).requires_grad_(True)
    eval_sh_cpu(3, sh, directions).sum().backward()


def tiny_step() -> None:
    """A render of four Gaussians over an environment, its SSIM and their backward pass on the
    CPU backend: every kernel of a training step runs once."""
    xyz = np.array([[0.0, 0.0, 2.0], [0.2, 0.0, 2.5], [0.0, 0.2, 3.0], [-0.2, 0.0, 2.2]])
    tiny = gaussians_from_points(xyz, np.full((4, 3), 128, np.uint8), initial_opacity=0.5)
    tiny = Gaussians(**{k: v.clone().requires_grad_(True) for k, v in tiny.tensors().items()})
    camera, pose, background = _tiny_view()
    out = render(
        tiny,
        camera,
        pose,
        background=background,
        with_features=True,
        feature_geometry_grad=False,
        feature_pixels=torch.arange(0, 256, 7),
        backend="cpu",
    )
    (mean_ssim_cpu(out.rgb, torch.zeros_like(out.rgb)) + out.features.sum()).backward()


def _tiny_view() -> tuple[PinholeCamera, torch.Tensor, torch.Tensor]:
    """The 16x16 camera of :func:`tiny_step` and :func:`tiny_parts` at the origin, its (3, 4)
    pose and its (16, 16, 3) background from a fresh environment, differentiable in the
    environment's parameters."""
    camera, pose = PinholeCamera(16, 16, 16.0, 16.0, 8.0, 8.0), torch.eye(4)[:3]
    return camera, pose, Environment(up=np.array([0.0, -1.0, 0.0]), bins=4)(camera, pose)


def _loop(
    folder: RunFolder,
    state: _State,
    views: TrainViews,
    cfg: TrainConfig,
    backend: Backend,
    stop_after: int | None,
    progress: bool,
) -> TrainResult:
    timing = cfg.timing
    warm_up(backend, progress)
    last = min(timing.iters, stop_after) if stop_after is not None else timing.iters
    start_time = time.perf_counter()
    with (
        stop_requests() as stop,
        tqdm(
            total=timing.iters, initial=state.step, desc="training", unit="it", disable=not progress, dynamic_ncols=True
        ) as bar,
    ):
        while state.step < last:
            step = state.step + 1
            losses = _train_step(state, views.at_step(step), cfg, backend, step)
            if not math.isfinite(losses["loss"]):
                kept = folder.checkpoint_files()
                raise TrainingDiverged(step, losses["loss"], kept[-1] if kept else None)
            state.step = step
            if step % LOG_EVERY == 0 or step == timing.iters:
                state.history.append({"step": step, **losses, "gaussians": len(state.gaussians)})
                bar.set_postfix(loss=f"{losses['loss']:.4f}", psnr=f"{losses['psnr']:.2f}", n=len(state.gaussians))
            bar.update(1)
            if step % timing.checkpoint_every == 0 or step == last or stop.requested:
                path = _save_checkpoint(folder, state)
            if stop.requested and step < last:
                bar.close()
                raise Interrupted(
                    f"{stop.signal_name} at step {step} of {timing.iters}: checkpoint {path} written; "
                    f"continue with `gsseg train SCENE --out {folder.root} --resume`."
                )
    finished = state.step >= timing.iters
    if finished:
        _export(folder, state)
    return TrainResult(
        run=folder.root,
        step=state.step,
        num_gaussians=len(state.gaussians),
        seconds=time.perf_counter() - start_time,
        finished=finished,
    )
