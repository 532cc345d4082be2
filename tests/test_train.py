"""The trainer: it fits a scene, resumes exactly, stops cleanly on divergence and refuses bad input."""

from __future__ import annotations

import json
import shutil

import cv2
import numpy as np
import pytest
import torch
from helpers import GEOMETRY, random_gaussians

from dataset_tools.image_files import read_mask
from dataset_tools.infra.errors import InputError
from dataset_tools.scene import load_scene
from gsseg.model.gaussians import Gaussians, gaussians_from_points
from gsseg.model.ply import read_ply
from gsseg.render.views import render_run
from gsseg.train import trainer as trainer_module
from gsseg.train.config import SCHEDULES, LearningRates, TrainConfig
from gsseg.train.optim import GaussianOptimizer
from gsseg.train.strategy import DensifyOptions, DensifyStats, densify_and_prune
from gsseg.train.trainer import TrainingDiverged, train
from gsseg.train.views import TrainViews, view_bytes


def _history(run):
    return json.loads((run / "metrics.json").read_text())["train"]["history"]


def test_training_fits_colour_and_objects(trained, small_scene, tmp_path):
    history = _history(trained)
    assert history[-1]["psnr"] > history[0]["psnr"] + 5
    assert history[-1]["obj"] < 0.5 * history[0]["obj"]
    g = read_ply(trained / "gaussians.ply")
    assert len(g) == history[-1]["gaussians"] and torch.isfinite(g.means).all()
    out = render_run(trained, small_scene.root, tmp_path / "r", split="train", colorize=True, progress=False)
    names = sorted(p.name for p in (out / "labels").glob("*.png"))
    assert names and names == sorted(p.name for p in (out / "rgb").glob("*.png"))
    assert len(list((out / "labels_color").glob("*.png"))) == len(names)
    agree = [np.mean(read_mask(out / "labels" / n) == read_mask(small_scene.root / "object_mask" / n)) for n in names]
    assert np.mean(agree) > 0.8


@pytest.mark.slow
def test_resume_continues_the_same_loss_curve(small_scene, tmp_path):
    cfg = TrainConfig(iters=40, backend="cpu")
    train(small_scene.root, tmp_path / "straight", cfg, progress=False)
    first = train(small_scene.root, tmp_path / "split", cfg, stop_after=23, progress=False)
    assert not first.finished and not (tmp_path / "split" / "gaussians.ply").exists()
    train(small_scene.root, tmp_path / "split", cfg, resume=True, progress=False)
    assert _history(tmp_path / "split") == _history(tmp_path / "straight")
    a, b = read_ply(tmp_path / "straight" / "gaussians.ply"), read_ply(tmp_path / "split" / "gaussians.ply")
    assert all(torch.equal(x, y) for x, y in zip(a.tensors().values(), b.tensors().values()))


def test_resume_keeps_its_options_and_its_scene(small_scene, tmp_path):
    """An option asked for on resume must be the recorded one (``iters`` may grow); options
    left at their defaults are taken from the run. A moved copy of the scene is the same
    scene; a copy with one photo changed is not."""
    cfg = TrainConfig(iters=20, backend="cpu", seed=2)
    train(small_scene.root, tmp_path / "run", cfg, stop_after=5, progress=False)
    for asked, message in (
        (TrainConfig(iters=20, backend="cpu", seed=3), "trained with seed=2, not 3"),
        (TrainConfig(iters=20, backend="cpu", seed=2, masks=None), "trained with masks='object_mask', not None"),
        (TrainConfig(iters=10, backend="cpu", seed=2), "only lengthen it, not shorten it to 10"),
    ):
        with pytest.raises(InputError, match=message):
            train(small_scene.root, tmp_path / "run", asked, resume=True, progress=False)
    with pytest.raises(InputError, match="trained with seed=2, not 0"):  # asked on a command line, though the default
        train(small_scene.root, tmp_path / "run", TrainConfig(), resume=True, given={"seed"}, progress=False)
    moved = shutil.copytree(small_scene.root, tmp_path / "moved")
    train(moved, tmp_path / "run", TrainConfig(), resume=True, stop_after=10, progress=False)
    changed = shutil.copytree(small_scene.root, tmp_path / "changed")
    first = sorted((changed / "images").iterdir())[0]
    cv2.imwrite(str(first), 255 - cv2.imread(str(first)))
    with pytest.raises(InputError, match=f"not the scene .* \\(the image of view {first.name} differs\\)"):
        train(changed, tmp_path / "run", TrainConfig(), resume=True, progress=False)
    result = train(small_scene.root, tmp_path / "run", TrainConfig(iters=30), resume=True, progress=False)
    assert result.finished and result.step == 30
    record = json.loads((tmp_path / "run" / "config.json").read_text())
    assert record["iters"] == 30 and record["seed"] == 2
    assert set(record["scene_fingerprint"]["views"]) == {v.name for v in load_scene(small_scene.root).views}


@pytest.mark.parametrize(
    "schedule, iters, resets",
    [
        ("gpu", None, [3000, 6000, 9000, 12000]),
        ("gpu", 15000, [3000, 6000]),
        ("gpu", 3000, []),
        ("gpu", 60000, [6000, 12000, 18000, 24000]),
        *(("cpu", iters, []) for iters in (None, 1000, 1500, 3000, 6000, 30000)),
    ],
)
def test_a_shorter_run_drops_opacity_resets_rather_than_compress_them(schedule, iters, resets):
    """A reset needs about as many steps to recover from whatever the run's length: its period
    stretches with ``--iters`` but never shrinks, and resets come only while densifying. The CPU
    schedule, too short to win a reset back, has none."""
    timing = TrainConfig(schedule=schedule, iters=iters).timing
    assert [s for s in range(1, timing.iters + 1) if timing.resets_opacity_at(s)] == resets
    base = SCHEDULES[schedule]
    assert timing.densify_until == round(base.densify_until * timing.iters / base.iters)  # the rest still scales


def test_config_keeps_what_a_run_was_trained_with():
    """A config round-trips through its JSON; a run recorded before ``geometry_from_masks``
    existed (its object loss shaped the geometry) resumes with that coupling."""
    cfg = TrainConfig(iters=10, seed=3)
    assert TrainConfig.from_json(json.loads(json.dumps(cfg.to_json()))) == cfg
    assert not cfg.geometry_from_masks
    older = {k: v for k, v in cfg.to_json().items() if k != "geometry_from_masks"}
    assert TrainConfig.from_json(older).geometry_from_masks


def test_masks_train_the_features_alone_unless_asked(small_scene, tmp_path):
    """By default the object loss leaves the geometry where colour alone puts it (same
    Gaussians, bit for bit, as training without it); --geometry-from-masks moves it."""
    runs = {}
    for name, cfg in {
        "colour": TrainConfig(iters=40, backend="cpu", gamma_obj=0.0),
        "default": TrainConfig(iters=40, backend="cpu"),
        "coupled": TrainConfig(iters=40, backend="cpu", geometry_from_masks=True),
    }.items():
        runs[name] = read_ply(train(small_scene.root, tmp_path / name, cfg, progress=False).run / "gaussians.ply")
    assert all(torch.equal(getattr(runs["default"], k), getattr(runs["colour"], k)) for k in GEOMETRY)
    assert not torch.equal(runs["default"].obj_feat, runs["colour"].obj_feat)
    assert len(runs["coupled"]) != len(runs["colour"]) or not torch.equal(runs["coupled"].means, runs["colour"].means)


def _outside_every_view(means: np.ndarray, views) -> np.ndarray:
    """(N,) bool: the points ``means`` (N, 3) whose centre lies behind every camera or more
    than an image's width outside its image, which no training pixel can draw."""
    outside = np.ones(len(means), bool)
    for view in views:
        pc = means @ view.cam_from_world[:, :3].T + view.cam_from_world[:, 3]
        with np.errstate(divide="ignore", invalid="ignore"):
            u = pc[:, 0] / pc[:, 2] * view.camera.fx + view.camera.cx
            v = pc[:, 1] / pc[:, 2] * view.camera.fy + view.camera.cy
        W, H = view.camera.width, view.camera.height
        near = (pc[:, 2] > 0) & (u > -W) & (u < 2 * W) & (v > -H) & (v < 2 * H)
        outside &= ~near
    return outside


@pytest.mark.parametrize("weight", [0.0, 0.05])
def test_the_opacity_term_fades_what_no_view_draws(small_scene, tmp_path, monkeypatch, weight):
    """Gaussians no training view draws get no photometric gradient: without the opacity term
    they keep their initial opacity; with it they fade."""
    views = load_scene(small_scene.root).split("train")
    centres = np.stack([v.center for v in views])
    rng = np.random.default_rng(0)
    far = centres.mean(0) + rng.normal(size=(1000, 3)) * 10 * np.ptp(centres, 0).max()
    spot = far[_outside_every_view(far, views)][0]  # a cluster of small Gaussians there, drawn by no view
    hidden = spot + rng.normal(size=(200, 3)) * 1e-3 * np.ptp(centres, 0).max()
    assert _outside_every_view(hidden, views).all()
    initial = trainer_module._initial_gaussians

    def with_hidden(scene, cfg):
        grey = np.full((len(hidden), 3), 128, np.uint8)
        return Gaussians.concat(
            initial(scene, cfg), gaussians_from_points(hidden, grey, initial_opacity=cfg.initial_opacity)
        )

    monkeypatch.setattr(trainer_module, "_initial_gaussians", with_hidden)
    cfg = TrainConfig(iters=40, backend="cpu", gamma_obj=0.0, opacity_reg=weight)
    run = train(small_scene.root, tmp_path / "run", cfg, progress=False).run
    g = read_ply(run / "gaussians.ply")
    unseen = torch.as_tensor(_outside_every_view(g.means.double().numpy(), views))
    assert unseen.sum() == len(hidden)  # none pruned: they stay above the threshold in 40 steps
    opacity = g.opacities[unseen]
    if weight == 0:
        assert torch.allclose(opacity, torch.full_like(opacity, cfg.initial_opacity))
    else:
        assert opacity.max() < 0.5 * cfg.initial_opacity


@pytest.mark.slow
def test_max_gaussians_caps_densification(small_scene, tmp_path):
    free = _history(
        train(small_scene.root, tmp_path / "free", TrainConfig(iters=60, backend="cpu"), progress=False).run
    )
    start = free[0]["gaussians"]
    assert max(h["gaussians"] for h in free) > start + 20  # densification does grow this scene
    cap = start + 20
    capped_cfg = TrainConfig(iters=60, backend="cpu", max_gaussians=cap)
    capped = _history(train(small_scene.root, tmp_path / "capped", capped_cfg, progress=False).run)
    assert max(h["gaussians"] for h in capped) <= cap
    assert json.loads((tmp_path / "capped" / "config.json").read_text())["timing"]["max_gaussians"] == cap


def test_densification_over_budget_takes_the_largest_gradients():
    """Every Gaussian is over the gradient threshold and small enough to be cloned, but only
    three more fit: exactly the three with the largest gradients are cloned."""
    g = random_gaussians(10, seed=3, dtype=torch.float32)
    g.opacity_logits = torch.full_like(g.opacity_logits, 3.0)  # nothing is pruned as transparent
    opt = GaussianOptimizer(g, LearningRates(), extent=100.0)
    grads = torch.tensor([5.0, 9.0, 1.0, 7.0, 2.0, 8.0, 3.0, 4.0, 6.0, 1.5]) * 1e-3
    stats = DensifyStats(grad_sum=grads.clone(), count=torch.ones(10), max_radii=torch.ones(10))
    options = DensifyOptions(
        grad_threshold=1e-4, percent_dense=0.01, prune_opacity=0.005, extent=100.0, max_gaussians=13
    )
    densify_and_prune(opt, stats, options, prune_large=False, generator=torch.Generator().manual_seed(0))
    means = opt.gaussians.means.detach()
    copies = [int((means == g.means[i]).all(dim=1).sum()) for i in range(10)]
    assert len(opt) == 13
    assert [i for i, c in enumerate(copies) if c == 2] == [1, 3, 5] and min(copies) == 1


def test_a_loss_that_turns_nan_stops_and_keeps_the_last_checkpoint(small_scene, tmp_path, monkeypatch):
    """Divergence is simulated by a photometric loss that returns NaN from step 12 on."""
    real = trainer_module.photometric_loss
    calls = {"n": 0}

    def loss_going_nan(*args):
        calls["n"] += 1
        value = real(*args)
        return value * float("nan") if calls["n"] >= 12 else value

    monkeypatch.setattr(trainer_module, "photometric_loss", loss_going_nan)
    with pytest.raises(TrainingDiverged, match="diverged at step 12.*step_0000010.pt") as failed:
        train(small_scene.root, tmp_path / "run", TrainConfig(iters=60, backend="cpu"), progress=False)
    assert failed.value.step == 12 and failed.value.checkpoint.name == "step_0000010.pt"
    assert not isinstance(failed.value, InputError)  # the input was good: the work failed
    kept = sorted(p.name for p in (tmp_path / "run" / "checkpoints").glob("*.pt"))
    assert kept == ["step_0000010.pt"]
    state = torch.load(tmp_path / "run" / "checkpoints" / kept[0], weights_only=False)
    assert all(torch.isfinite(v).all() for v in state["gaussians"]["params"].values())


def test_bad_input_is_refused(small_scene, tmp_path):
    no_model = tmp_path / "no_model"
    shutil.copytree(small_scene.root, no_model)
    shutil.rmtree(no_model / "sparse")
    with pytest.raises(InputError, match="sparse"):
        train(no_model, tmp_path / "a", TrainConfig(iters=2, backend="cpu"), progress=False)

    wrong_masks = tmp_path / "wrong_masks"
    shutil.copytree(small_scene.root, wrong_masks)
    mask = next((wrong_masks / "object_mask").glob("*.png"))
    cv2.imwrite(str(mask), np.zeros((10, 10), np.uint8))
    with pytest.raises(InputError, match="masks must have the size of their image"):
        train(wrong_masks, tmp_path / "b", TrainConfig(iters=2, backend="cpu"), progress=False)

    train(small_scene.root, tmp_path / "c", TrainConfig(iters=2, backend="cpu"), progress=False)
    with pytest.raises(InputError, match="already holds a run"):
        train(small_scene.root, tmp_path / "c", TrainConfig(iters=2, backend="cpu"), progress=False)


def test_views_in_memory_are_uint8_and_on_disk_are_read_ahead(small_scene):
    scene = load_scene(small_scene.root, masks="object_mask")
    views = scene.split("train")
    order = [3, 0, 2, 1, 4, 5, 6, 2, 1, 0]
    memory = TrainViews(views, lambda step: order[step % len(order)], mode="memory", progress=False)
    assert memory.resident_bytes == view_bytes(views) == 4 * 96 * 96 * len(views)
    disk = TrainViews(views, lambda step: order[step % len(order)], mode="disk", prefetch=2, progress=False)
    assert disk.resident_bytes == 0
    for step in range(1, 8):
        a, b = memory.at_step(step), disk.at_step(step)
        assert a.name == b.name == views[order[step]].name
        assert a.image.dtype == torch.float32 and torch.equal(a.image, b.image) and torch.equal(a.mask, b.mask)
        assert torch.equal(a.image, torch.from_numpy(views[order[step]].load_image().astype(np.float32) / 255.0))
    disk.close()
    assert disk.resident_bytes == 0
    with pytest.raises(InputError, match="cache_views='swap'"):
        TrainViews(views, lambda step: 0, mode="swap", progress=False)


def test_training_from_disk_writes_the_bytes_of_training_from_memory(small_scene, tmp_path):
    cfg = TrainConfig(iters=30, backend="cpu")
    for mode in ("memory", "disk"):
        train(small_scene.root, tmp_path / mode, cfg, cache_views=mode, progress=False)
    assert (tmp_path / "memory" / "gaussians.ply").read_bytes() == (tmp_path / "disk" / "gaussians.ply").read_bytes()


def test_the_training_ssim_is_kornias_in_value_and_gradient():
    """:func:`ssim_map` against ``kornia.metrics.ssim`` (the reference, 11x11 window) on two
    random image pairs of odd sizes: the same map and the same gradient."""
    import kornia

    from gsseg.train.losses import ssim_map

    gen = torch.Generator().manual_seed(0)
    for shape in ((1, 3, 37, 52), (2, 1, 20, 15)):
        a = torch.rand(shape, generator=gen, dtype=torch.float64)
        b = (a + 0.2 * torch.rand(shape, generator=gen, dtype=torch.float64)).clamp(0, 1)
        grads = []
        for fn in (ssim_map, lambda x, y: kornia.metrics.ssim(x, y, 11)):
            x = a.clone().requires_grad_(True)
            value = fn(x, b)
            (value * torch.linspace(0, 1, value.numel(), dtype=torch.float64).view(value.shape)).sum().backward()
            grads.append((value.detach(), x.grad))
        torch.testing.assert_close(grads[0][0], grads[1][0], atol=1e-10, rtol=0)
        torch.testing.assert_close(grads[0][1], grads[1][1], atol=1e-8, rtol=0)


@pytest.mark.parametrize("shape", [(37, 52, 3), (6, 9, 1), (12, 6, 2), (64, 71, 3)])
def test_the_cpu_ssim_kernels_give_the_reference_value_and_gradient(shape):
    """The numba mean SSIM against :func:`ssim_map` (itself kornia's) in float32, on sizes
    from the smallest that reflect padding allows to ones with a wide interior."""
    from gsseg.train.losses import ssim_map
    from gsseg.train.ssim_cpu import mean_ssim_cpu

    gen = torch.Generator().manual_seed(1)
    a = torch.rand(shape, generator=gen)
    b = (a + 0.3 * torch.rand(shape, generator=gen) - 0.15).clamp(0, 1)
    results = []
    for fn in (mean_ssim_cpu, lambda x, y: ssim_map(x.permute(2, 0, 1)[None], y.permute(2, 0, 1)[None]).mean()):
        x = a.clone().requires_grad_(True)
        value = fn(x, b)
        (3.0 * value).backward()
        results.append((value.detach(), x.grad))
    torch.testing.assert_close(results[0][0], results[1][0], atol=2e-6, rtol=0)
    scale = results[1][1].abs().max()
    torch.testing.assert_close(results[0][1] / scale, results[1][1] / scale, atol=2e-5, rtol=0)


def test_reflect_taps_are_the_padded_filter_and_its_transpose():
    """The tables of :func:`reflect_taps` as dense matrices: the forward one is np.pad's reflect
    followed by the window, the transposed one its transpose."""
    from gsseg.train.ssim_cpu import SSIM_WINDOW, gaussian_window, reflect_taps

    g, r = gaussian_window().astype(np.float64), SSIM_WINDOW // 2
    for n in (6, 11, 23):
        dense = np.zeros((n, n))
        for i in range(n):
            unit = np.zeros(n)
            unit[i] = 1.0
            dense[:, i] = np.convolve(np.pad(unit, r, mode="reflect"), g, mode="valid")
        for transpose, expected in ((False, dense), (True, dense.T)):
            index, weights, lo, hi = reflect_taps(n, transpose)
            table = np.zeros((n, n))
            np.add.at(table, (np.repeat(np.arange(n), index.shape[1]), index.ravel()), weights.ravel())
            np.testing.assert_allclose(table, expected, atol=1e-7)
            assert all(np.count_nonzero(weights[i]) == SSIM_WINDOW for i in range(lo, hi))
