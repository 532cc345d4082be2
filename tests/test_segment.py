"""Segmentation: contribution matrix, reassignment, prompts and edits."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from dataset_tools.cameras import PinholeCamera
from dataset_tools.infra.errors import InputError
from gsseg.edits import apply_edit, edit_runs
from gsseg.model.gaussians import Gaussians
from gsseg.model.ply import read_ply
from gsseg.render import BACKENDS, render
from gsseg.render.contributions import REGION_WEIGHT_FLOOR, Contributions, MaskedView, contribution_matrix
from gsseg.run.folder import RunFolder
from gsseg.segment.label_options import LabelOptions
from gsseg.segment.prompts import object_at_point
from gsseg.segment.reassign import reassign

F, SIZE = 20.0, 16


def _two_gaussians() -> Gaussians:
    """An isotropic Gaussian at depth 2 (opacity 0.6) in front of one at depth 3 (opacity 0.8),
    both on the optical axis of a 16x16 camera."""
    return Gaussians(
        means=torch.tensor([[0.0, 0.0, 2.0], [0.0, 0.0, 3.0]]),
        log_scales=torch.log(torch.tensor([[0.2] * 3, [0.3] * 3])),
        quats=torch.tensor([[1.0, 0, 0, 0]] * 2),
        opacity_logits=torch.logit(torch.tensor([0.6, 0.8])),
        sh_dc=torch.tensor([[1.0, 0, 0], [0, 0, 1.0]]),
        sh_rest=torch.zeros(2, 15, 3),
        obj_feat=torch.zeros(2, 16),
    )


def _camera() -> tuple[PinholeCamera, np.ndarray]:
    return PinholeCamera(SIZE, SIZE, F, F, SIZE / 2, SIZE / 2), np.eye(4)[:3]


def _hand_alphas(g: Gaussians) -> np.ndarray:
    """(2, H, W) alpha of each Gaussian at each pixel, from the formula of an isotropic
    Gaussian facing the camera: o exp(-|d|^2 / (2 ((f s / z)^2 + 0.3)))."""
    yy, xx = np.meshgrid(np.arange(SIZE) + 0.5, np.arange(SIZE) + 0.5, indexing="ij")
    out = []
    for mean, s, o in zip(g.means.numpy(), g.scales[:, 0].numpy(), g.opacities.numpy()):
        u, v = F * mean[0] / mean[2] + SIZE / 2, F * mean[1] / mean[2] + SIZE / 2
        var = (F * s / mean[2]) ** 2 + 0.3
        a = o * np.exp(-((xx - u) ** 2 + (yy - v) ** 2) / (2 * var))
        out.append(np.where(a >= 1 / 255, np.minimum(a, 0.99), 0.0))
    return np.stack(out)


@pytest.mark.parametrize(
    "backend",
    [
        "cpu",
        "torch",
        pytest.param(
            "gsplat",
            marks=pytest.mark.skipif(
                not BACKENDS["gsplat"].available(), reason="the gsplat backend needs gsplat and a CUDA GPU"
            ),
        ),
    ],
)
def test_contribution_matrix_equals_hand_computed_alpha_t_sums(backend):
    g = _two_gaussians()
    cam, pose = _camera()
    mask = np.zeros((SIZE, SIZE), np.uint8)
    mask[:, : SIZE // 2], mask[:, SIZE // 2 :], mask[:4] = 3, 7, 0
    a = _hand_alphas(g)
    weights = np.stack([a[0], a[1] * (1 - a[0])])  # alpha_i T_i, front to back
    expected = np.stack([weights[:, mask == label].sum(1) for label in (0, 3, 7)])
    got = contribution_matrix(g, [MaskedView(cam, pose, mask)] * 2, backend=backend, progress=False)
    assert got.labels.tolist() == [0, 3, 7]
    np.testing.assert_allclose(got.weights.numpy(), 2 * expected, rtol=1e-4, atol=1e-6)
    # Each view's own sums, a row per label it shows, without the weights under the floor.
    one_label = np.full_like(mask, 3)
    views = [MaskedView(cam, pose, mask), MaskedView(cam, pose, one_label)]
    regions = contribution_matrix(g, views, backend=backend, regions=True, progress=False).regions
    assert regions.view.tolist() == [0, 0, 0, 1] and regions.label.tolist() == [0, 3, 7, 3]
    rows = np.vstack([expected, weights.reshape(2, -1).sum(1)])
    np.testing.assert_allclose(
        regions.matrix.toarray(), np.where(rows >= REGION_WEIGHT_FLOOR, rows, 0.0), rtol=1e-4, atol=1e-6
    )


def _contributions(weights, labels=(0, 1, 2)) -> Contributions:
    return Contributions(labels=np.array(labels, np.uint8), weights=torch.tensor(weights, dtype=torch.float32))


def test_gamma_zero_reduces_prior_to_plain_voting():
    rng = np.random.default_rng(0)
    w = rng.random((3, 500)) * (rng.random(500) > 0.1)  # 10% of the Gaussians never observed
    prior = torch.as_tensor(rng.integers(0, 3, 500))
    p = torch.as_tensor(rng.random(500), dtype=torch.float32)
    seg = reassign(_contributions(w), prior, p, LabelOptions(method="prior", gamma_p=0.0))
    observed = w.sum(0) > 0
    assert np.array_equal(seg.labels[observed], w.argmax(0)[observed])
    assert np.array_equal(seg.labels[~observed], prior.numpy()[~observed])


def test_prior_is_added_to_per_gaussian_shares_so_gamma_is_scale_free():
    # Gaussian 0 is seen 55% under label 1 and 45% under label 2; its classifier says 2 with p = 1.
    for scale in (1.0, 1000.0):
        c = _contributions([[0.0], [0.55 * scale], [0.45 * scale]])

        def label(gamma: float) -> int:
            return reassign(c, torch.tensor([2]), torch.tensor([1.0]), LabelOptions(gamma_p=gamma)).labels[0]

        assert label(0.0) == 1 and label(0.2) == 2 and label(0.05) == 1 and label(-1.0) == 1


def test_binary_mode_matches_a_per_object_loop():
    rng = np.random.default_rng(1)
    w = rng.random((4, 300)) ** 3
    prior = torch.as_tensor(rng.integers(0, 4, 300))
    p = torch.as_tensor(rng.random(300), dtype=torch.float32)
    seg = reassign(_contributions(w, (0, 1, 2, 5)), prior, p, LabelOptions(mode="binary"))
    share = w / w.sum(0)
    for row, obj in enumerate([1, 2, 5], start=1):
        mine = prior.numpy() == obj
        fg = share[row] + 0.2 * p.numpy() * mine
        rest = 1 - share[row] + 0.2 * p.numpy() * ~mine
        assert np.array_equal(seg.selection(obj), fg > rest)
    # a Gaussian's label is the last object, in ID order, that selects it (0 if none does);
    # a negative prior lowers the rest side of every other object, so selections overlap
    seg = reassign(_contributions(w, (0, 1, 2, 5)), prior, p, LabelOptions(mode="binary", gamma_p=-1.0))
    sel = np.stack([seg.selection(obj) for obj in (1, 2, 5)])
    assert sel.sum(0).max() > 1 and not sel.any(0).all()
    expected = np.where(sel.any(0), np.array([1, 2, 5])[2 - np.argmax(sel[::-1], axis=0)], 0)
    assert np.array_equal(seg.labels, expected)
    with pytest.raises(InputError, match="object 9 is not among"):
        seg.selection(9)


def test_point_prompt_picks_the_object_around_it():
    rng = np.random.default_rng(2)
    centres = np.array([[0, 0, 0], [3, 0, 0], [0, 3, 0]], float)
    means = np.concatenate([c + 0.3 * rng.standard_normal((100, 3)) for c in centres])
    labels = np.repeat([4, 9, 2], 100).astype(np.uint8)
    labels[rng.choice(300, 20, replace=False)] = 0  # a few mislabelled Gaussians do not matter
    assert object_at_point(means, labels, np.array([2.9, 0.1, 0.0])) == 9
    assert object_at_point(means, labels, np.array([0.1, 2.8, 0.1])) == 2
    with pytest.raises(InputError, match="outside the scene bounds"):
        object_at_point(means, labels, np.array([50.0, 0.0, 0.0]))


def test_removing_the_front_object_shows_what_lies_behind():
    g = _two_gaussians()
    cam, pose = _camera()
    pose = torch.as_tensor(pose, dtype=torch.float32)
    removed = apply_edit(g, np.array([True, False]), "remove")
    after = render(removed, cam, pose).rgb
    behind_alone = render(g.select(torch.tensor([False, True])), cam, pose).rgb
    torch.testing.assert_close(after, behind_alone)
    before = render(g, cam, pose).rgb
    centre = before[SIZE // 2, SIZE // 2]
    assert centre[0] > centre[2] and after[SIZE // 2, SIZE // 2, 2] > after[SIZE // 2, SIZE // 2, 0]


def test_recolor_keeps_shading_and_extract_keeps_only_the_object():
    g = _two_gaussians()
    g.sh_dc[0] = torch.tensor([0.5, 0.2, 0.1])
    recolored = apply_edit(g, np.array([True, False]), "recolor", (0.0, 1.0, 0.0))
    assert torch.equal(recolored.sh_dc[1], g.sh_dc[1])
    rgb = recolored.sh_dc[0] * 0.28209479177387814 + 0.5
    assert rgb[1] > 0.9 and rgb[0] < 0.05 and rgb[2] < 0.05
    assert len(apply_edit(g, np.array([False, True]), "extract")) == 1
    with pytest.raises(InputError, match="needs color"):
        apply_edit(g, np.array([True, False]), "recolor")


def test_segment_edit_and_render_segments_from_the_command_line(trained, small_scene, tmp_path):
    import shutil
    import subprocess

    from helpers import script

    from dataset_tools.image_files import read_image, read_mask
    from dataset_tools.scene import load_scene

    run = tmp_path / "run"
    shutil.copytree(trained, run)
    gsseg = script("gsseg")

    def ok(*args):
        r = subprocess.run([gsseg, *map(str, args)], capture_output=True, text=True)
        assert r.returncode == 0, r.stderr
        return r

    ok("segment", run, "--scene", small_scene.root)
    seg = RunFolder(run).read_labels()
    assert set(seg.objects.tolist()) == {1, 2, 3, 4}
    ok("render", run, "--scene", small_scene.root, "--out", tmp_path / "r", "--what", "segments", "--split", "train")
    scene = load_scene(small_scene.root)
    agree = [
        np.mean(read_mask(tmp_path / "r" / "segments" / f"{v.stem}.png") == v.load_mask()) for v in scene.split("train")
    ]
    assert np.mean(agree) > 0.8

    # A point at the centre of object 2's Gaussians selects object 2; removing it edits only them.
    means = read_ply(run / "gaussians.ply").means
    point = np.median(means[torch.as_tensor(seg.selection(2))].numpy(), axis=0)
    ok("edit", run, "--point", *point, "--op", "remove", "--name", "gone", "--split", "train", "--no-fill")
    edit = json.loads((run / "edits" / "gone" / "edit.json").read_text())
    assert edit["object_id"] == 2 and edit["selected_gaussians"] == int(seg.selection(2).sum())
    assert edit["labels"] == {"method": "prior", "mode": "multi", "gamma_p": 0.2, "smooth": 0, "fill": False}
    frames = sorted((run / "edits" / "gone" / "renders").glob("*.png"))
    assert len(frames) == len(scene.split("train")) and (run / "edits" / "gone" / "video.mp4").stat().st_size > 0
    assert read_image(frames[0]).shape == (96, 96, 3)

    # Several edits of one selection, made once: each folder as its own edit writes it.
    chosen, both = edit_runs(
        run,
        {"remove": None, "recolor": (255, 0, 0)},
        names={"remove": "gone2"},
        point=point,
        split="train",
        fill=None,
        progress=False,
    )
    assert [p.name for p in both] == ["gone2", "recolor_2"] and chosen.object_id == 2
    assert (both[0] / "gaussians.ply").read_bytes() == (run / "edits" / "gone" / "gaussians.ply").read_bytes()
    record = json.loads((both[0] / "edit.json").read_text())
    # The CLI's point is rounded, and its process sums the ghost share on another thread count.
    for rounded in ("point", "ghost_share"):
        assert record.pop(rounded) == pytest.approx(edit.pop(rounded), rel=1e-6)
    assert record == edit
    recoloured = read_ply(both[1] / "gaussians.ply").sh_dc
    changed = (recoloured != read_ply(run / "gaussians.ply").sh_dc).any(-1).numpy()
    assert changed.any() and not (changed & ~seg.selection(2)).any()

    r = subprocess.run([gsseg, "edit", str(run), "--object-id", "42", "--op", "remove"], capture_output=True, text=True)
    assert r.returncode == 2 and "object 42 is not among" in r.stderr and "Traceback" not in r.stderr
    r = subprocess.run(
        [gsseg, "edit", str(trained), "--object-id", "1", "--op", "remove"], capture_output=True, text=True
    )
    assert r.returncode == 2 and "run `gsseg segment`" in r.stderr


def test_segment_votes_with_the_masks_the_run_was_trained_on(segmented, scene_copy, tmp_path):
    """A run trained on a mask folder of another name (the demo's ``hqmask``) is segmented
    from it without ``--masks``: the same labels as from ``object_mask``."""
    import shutil

    from gsseg.segment.segment_run import segment_run

    run = tmp_path / "run"
    shutil.copytree(segmented, run)
    config = json.loads((run / "config.json").read_text())
    assert config["masks"] == "object_mask"
    (run / "config.json").write_text(json.dumps({**config, "masks": "hqmask"}))
    (scene_copy / "object_mask").rename(scene_copy / "hqmask")
    result = segment_run(run, scene_copy, backend="cpu", progress=False)
    np.testing.assert_array_equal(result.labels, RunFolder(segmented).read_labels().labels)
    with pytest.raises(InputError, match="object_mask: holds no masks"):
        segment_run(run, scene_copy, masks="object_mask", backend="cpu", progress=False)


def test_a_run_trained_on_colour_alone_segments_only_with_masks_named(small_scene, tmp_path):
    """No fallback to the scene's ``object_mask`` (a synthetic scene's ground truth)."""
    from gsseg.segment.segment_run import segment_run
    from gsseg.train.config import TrainConfig
    from gsseg.train.trainer import train

    run = tmp_path / "colour"
    train(small_scene.root, run, TrainConfig(iters=3, masks=None, backend="cpu"), progress=False)
    with pytest.raises(InputError, match="trained on colour alone.*name one with masks"):
        segment_run(run, small_scene.root, backend="cpu", progress=False)
    labels = segment_run(run, small_scene.root, masks="object_mask", backend="cpu", progress=False)
    assert labels.gamma_p == 0.0  # the classifier knows no mask IDs: the prior is left out
    assert RunFolder(run).read_contributions().masks == "object_mask"
