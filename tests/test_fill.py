"""The fill of a removal (gsseg.fill): which pixels no view saw, which space a view saw
through, the crop a fit renders, the inpainting, and a fill on a drawn scene with a known
answer: a red wall behind a blue box that every view sees from the front."""

import json
import shutil
import subprocess
from pathlib import Path

import cv2
import numpy as np
import pytest
import torch
from helpers import QUICK_FILL, script

from dataset_tools.cameras import PinholeCamera
from gsseg.fill import (
    crop_camera,
    fill_removal,
    inpaint,
    seen_through,
    surface_across,
    unseen_pixels,
)
from gsseg.fill_options import FillOptions
from gsseg.model.gaussians import gaussians_from_points
from gsseg.model.ply import read_ply
from gsseg.render import render
from gsseg.render.contributions import MaskedView
from gsseg.run.loaded import load_run

CAMERA = PinholeCamera(48, 40, 40.0, 40.0, 24.0, 20.0)


def _pose(x: float) -> np.ndarray:
    """(3, 4) cam_from_world of a camera at (x, 0, 0) looking down +z."""
    return np.concatenate([np.eye(3), [[-x], [0.0], [0.0]]], 1)


def _wall_depth(distance: float) -> np.ndarray:
    return np.full((CAMERA.height, CAMERA.width), distance, np.float32)


def test_unseen_pixels_known_answer():
    """A wall at z = 5 seen by a second camera 1 unit aside: the hole's pixels whose wall point
    falls in its image are seen, unless that camera shows something nearer there (an
    occluder), or shows the wall at another depth; a pixel showing the environment is seen
    where the other camera shows the environment in that direction."""
    hole = np.zeros((CAMERA.height, CAMERA.width), bool)
    hole[10:30, 10:38] = True
    other = (CAMERA, _pose(1.0), _wall_depth(5.0))
    seen_all = unseen_pixels(hole, _wall_depth(5.0), CAMERA, _pose(0.0), [other], 0.02)
    # the wall point of pixel u lands at u - 8 in the other camera (f = 40, baseline 1, depth 5)
    assert not seen_all.any()
    occluded = _wall_depth(5.0)
    occluded[:, 10:20] = 2.0
    out = unseen_pixels(hole, _wall_depth(5.0), CAMERA, _pose(0.0), [(CAMERA, _pose(1.0), occluded)], 0.02)
    assert out[10:30, 18:28].all() and not out[10:30, 10:18].any() and not out[10:30, 28:38].any()
    assert not (out & ~hole).any()
    far = unseen_pixels(hole, np.zeros_like(hole, np.float32), CAMERA, _pose(0.0), [other], 0.02)
    assert far[hole].all()  # the other camera shows the wall where the environment would be
    sky = (CAMERA, _pose(1.0), np.zeros_like(hole, np.float32))
    assert not unseen_pixels(hole, np.zeros_like(hole, np.float32), CAMERA, _pose(0.0), [sky], 0.02).any()


def test_seen_through_known_answer():
    """In front of the wall a camera shows: seen through; on it or behind it: not; outside
    every image: not; where the camera shows the environment: seen through."""
    view = (CAMERA, _pose(0.0), _wall_depth(5.0))
    points = np.array([[0, 0, 3.0], [0, 0, 5.0], [0, 0, 7.0], [100.0, 0, 5.0]])
    np.testing.assert_array_equal(seen_through(points, [view], 0.02), [True, False, False, False])
    sky = (CAMERA, _pose(0.0), np.zeros_like(_wall_depth(5.0)))
    np.testing.assert_array_equal(seen_through(points, [sky], 0.02), [True, True, True, False])


def test_crop_renders_the_crop():
    """A crop's camera renders the crop of the whole view (of Gaussians inside its field of
    view, where the projection's clamp, 1.3 half-widths about the axis as in 3D-GS, is
    the same)."""
    rng = np.random.default_rng(0)
    g = gaussians_from_points(rng.normal([0, 0, 5], 0.3, (300, 3)), rng.integers(0, 255, (300, 3)), initial_opacity=0.7)
    pose = torch.as_tensor(_pose(0.0), dtype=torch.float32)
    full = render(g, CAMERA, pose, with_features=False, backend="cpu").rgb
    part = render(g, crop_camera(CAMERA, 7, 5, 30, 33), pose, with_features=False, backend="cpu").rgb
    torch.testing.assert_close(part, full[5:33, 7:30], atol=1e-4, rtol=0)  # float sums in another order


def test_inpaint_carries_stripes_on():
    """A block missing from vertical stripes comes back closer to the stripes than their mean
    colour would be, and the known pixels away from it are kept."""
    x = np.arange(64)
    stripes = np.where((x // 4) % 2 == 0, 200, 40).astype(np.uint8)
    rgb = np.repeat(np.tile(stripes, (64, 1))[..., None], 3, 2)
    missing = np.zeros((64, 64), bool)
    missing[24:40, 24:40] = True
    out = inpaint(rgb, missing)
    error = np.abs(out[missing].astype(float) - rgb[missing]).mean()
    assert error < 0.5 * np.abs(rgb[missing].astype(float) - rgb.mean()).mean()
    np.testing.assert_array_equal(out[:20], rgb[:20])


def test_inpaint_draws_nothing_from_what_stands_in_front():
    """A hole in a grey wall beside a yellow occluder: left in, the occluder's colour bleeds
    into the hole; excluded, the hole comes back grey and the occluder is kept."""
    rgb = np.full((64, 64, 3), 120, np.uint8)
    occluder = np.zeros((64, 64), bool)
    occluder[20:44, 36:48] = True
    rgb[occluder] = (230, 200, 30)
    missing = np.zeros((64, 64), bool)
    missing[22:42, 20:35] = True
    bleeding = np.abs(inpaint(rgb, missing)[missing].astype(float) - 120).mean()
    out = inpaint(rgb, missing, occluder)
    assert np.abs(out[missing].astype(float) - 120).mean() < min(2.0, 0.25 * bleeding)
    np.testing.assert_array_equal(out[~missing], rgb[~missing])


def _box_scene():
    """A red wall of Gaussians at z = 6 with a hole behind a blue box at z = 4, as training
    leaves a wall where no view saw it; three cameras 0.1 apart see the box from the front."""
    u, v = np.meshgrid(np.linspace(-5, 5, 81), np.linspace(-4, 4, 65))
    wall = np.stack([u.ravel(), v.ravel(), np.full(u.size, 6.0)], 1)
    behind = (np.abs(wall[:, 0]) < 1.2) & (np.abs(wall[:, 1]) < 1.2)
    wall = wall[~behind]
    g_u, g_v = np.meshgrid(np.linspace(-0.6, 0.6, 13), np.linspace(-0.6, 0.6, 13))
    box = np.stack([g_u.ravel(), g_v.ravel(), np.full(g_u.size, 4.0)], 1)
    xyz = np.concatenate([wall, box])
    rgb = np.concatenate([np.tile([200, 40, 40], (len(wall), 1)), np.tile([40, 40, 200], (len(box), 1))])
    g = gaussians_from_points(xyz, rgb.astype(np.uint8), initial_opacity=0.95)
    g.log_scales = torch.full_like(g.log_scales, np.log(0.09))
    removed = np.zeros(len(g), bool)
    removed[len(wall) :] = True
    views = [MaskedView(CAMERA, _pose(x), np.zeros((CAMERA.height, CAMERA.width), np.uint8)) for x in (-0.1, 0, 0.1)]
    return g, removed, views


@pytest.mark.parametrize("fit_views", [FillOptions.fit_views, 1])
def test_fill_puts_the_wall_back(fit_views):
    """Removing the box leaves a black hole in the wall no view saw; the fill makes it red,
    seen from a camera between the training views, and leaves the rest of the view as it was;
    also called where gradients are off (as the evaluation renders); also fitted in one of the
    three views (a capture of many views is fitted in a few of them)."""
    g, removed, views = _box_scene()
    with torch.no_grad():
        filled = fill_removal(
            g,
            removed,
            views,
            environment=None,
            sh_degree=0,
            extent=1.0,
            options=FillOptions(steps=150, fit_views=fit_views),
            progress=False,
        )
    assert filled.added > 0 and filled.unseen_share > 0.5
    pose = torch.as_tensor(_pose(0.05), dtype=torch.float32)
    plain = render(g.select(torch.as_tensor(~removed)), CAMERA, pose, sh_degree=0, with_features=False).rgb.numpy()
    after = render(filled.gaussians, CAMERA, pose, sh_degree=0, with_features=False).rgb.numpy()
    box = render(g.select(torch.as_tensor(removed)), CAMERA, pose, sh_degree=0, with_features=False).alpha.numpy() > 0.5
    red = np.array([200, 40, 40]) / 255
    before_error = np.abs(plain[box] - red).mean()
    after_error = np.abs(after[box] - red).mean()
    assert before_error > 0.2 and after_error < 0.25 * before_error
    away = cv2.dilate(box.astype(np.uint8), np.ones((7, 7), np.uint8)) == 0
    assert np.abs(after[away] - plain[away]).max() < 0.02


def test_gsseg_edit_fills_a_removal_unless_told_not_to_plumbing(segmented, small_scene, tmp_path):
    """Plumbing: ``gsseg edit --op remove`` writes the removal with its fill after it, and says
    so in edit.json (with the fit's steps, those of ``QUICK_FILL`` here); ``--no-fill`` writes
    the removal alone, and with ``--fill-steps`` too is one sentence, exit 2, nothing written."""
    run_dir = Path(shutil.copytree(segmented, tmp_path / "run"))
    obj = int(load_run(run_dir).labels().objects[0])
    common = ["edit", str(run_dir), "--object-id", str(obj), "--op", "remove", "--backend", "cpu"]
    for name, flags in (("filled", ["--fill-steps", str(QUICK_FILL.steps)]), ("plain", ["--no-fill"])):
        r = subprocess.run([script("gsseg"), *common, "--name", name, *flags], capture_output=True, text=True)
        assert r.returncode == 0, r.stderr
    both = ["--name", "both", "--no-fill", "--fill-steps", "60"]
    r = subprocess.run([script("gsseg"), *common, *both], capture_output=True, text=True)
    assert r.returncode == 2, r.stderr
    assert r.stderr == "error: --fill-steps 60 with --no-fill: give the one or the other.\n"
    assert not (run_dir / "edits" / "both").exists()
    filled, plain = (read_ply(run_dir / "edits" / n / "gaussians.ply") for n in ("filled", "plain"))
    record = json.loads((run_dir / "edits" / "filled" / "edit.json").read_text())["removal_fill"]
    assert record["added"] == len(filled) - len(plain) and 0 <= record["unseen_share"] <= 1
    assert record["steps"] == QUICK_FILL.steps
    assert json.loads((run_dir / "edits" / "plain" / "edit.json").read_text())["removal_fill"] is None
    for name, value in plain.tensors().items():
        assert torch.equal(getattr(filled, name)[: len(plain)], value), name
    out = tmp_path / "filled.ply"  # gsseg export of the edit writes the filled model
    r = subprocess.run(
        [script("gsseg"), "export", str(run_dir), "--edit", "filled", "--out", str(out), "--no-environment"],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 0, r.stderr
    assert torch.equal(read_ply(out).means, filled.means)


def test_surface_across_carries_a_tilted_plane_over_the_hole_despite_an_occluder():
    """A floor seen at a slant (inverse depth affine in the pixel's ray) with a hole: the hole
    gets the floor's depth, although a near occluder covers part of the ring around it; a hole
    with no surface around it stays 0."""
    u, v = np.meshgrid(np.arange(CAMERA.width) + 0.5, np.arange(CAMERA.height) + 0.5)
    x, y = (u - CAMERA.cx) / CAMERA.fx, (v - CAMERA.cy) / CAMERA.fy
    floor = (1 / (0.02 * x + 0.1 * y + 0.2)).astype(np.float32)
    hole = np.zeros_like(floor, bool)
    hole[14:26, 16:32] = True
    depth = np.where(hole, 0.0, floor).astype(np.float32)
    depth[10:16, 12:20] = 1.5  # an occluder over a corner of the ring
    out = surface_across(hole, depth, CAMERA, radius=5, tolerance=0.02)
    np.testing.assert_allclose(out[hole], floor[hole], rtol=0.01)
    np.testing.assert_array_equal(out[~hole], depth[~hole])
    assert not surface_across(hole, np.zeros_like(depth), CAMERA, radius=5, tolerance=0.02).any()


def test_a_point_behind_an_occluders_edge_is_not_seen_through():
    """An occluder's edge pixel blends it with the wall behind, so its depth lies between: a
    point behind the occluder, just inside its edge, is hidden, not seen through."""
    depth = _wall_depth(5.0)
    depth[:, :24] = 2.0  # an occluder over the left half
    depth[:, 24] = 3.5  # its edge pixel, blended
    point = np.array([[(24.5 - CAMERA.cx) / CAMERA.fx * 3.0, 0.0, 3.0]])  # behind the occluder, in the edge pixel
    assert not seen_through(point, [(CAMERA, _pose(0.0), depth)], 0.02).any()
    assert seen_through(point + [[0.4, 0, 0]], [(CAMERA, _pose(0.0), depth)], 0.02).all()  # past the edge
