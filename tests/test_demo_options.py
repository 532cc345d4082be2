"""The demo's training sized to the capture: known answers of the rule and what it prints."""

from pathlib import Path

import cv2
import numpy as np
import pytest

from dataset_tools import colmap
from dataset_tools.cameras import PinholeCamera
from pipeline.demo import demo_training
from pipeline.demo_options import (
    EMBEDDED_ITERS,
    FULL_RUN_VIEWS,
    MAX_SCENE_GAUSSIANS,
    MAX_SCENE_ITERS,
    MIN_SCENE_GAUSSIANS,
    MIN_SCENE_ITERS,
    RUN_PIXELS,
    DemoOptions,
    capture_gaussians,
    capture_iters,
    capture_pixels,
)


def _capture(root: Path, size: int, points: int, folder: str = "images", views: int = 1) -> Path:
    """A capture of ``views`` black ``size`` x ``size`` views, all from one pose, and an SfM
    model of ``points`` points."""
    (root / folder).mkdir(parents=True)
    names = [f"{k:03d}.png" for k in range(views)]
    for name in names:
        cv2.imwrite(str(root / folder / name), np.zeros((size, size, 3), np.uint8))
    rng = np.random.default_rng(0)
    xyz = rng.normal(0, 1, (points, 3)) + [0, 0, 5]
    camera = PinholeCamera(size, size, size, size, size / 2, size / 2)
    uv = xyz[:, :2] / xyz[:, 2:] * size + size / 2
    colmap.write_model(
        root / "sparse" / "0",
        names,
        [camera] * views,
        [np.eye(4)[:3]] * views,
        [(np.arange(points), uv)] * views,
        xyz,
        np.zeros((points, 3), np.uint8),
    )
    return root


@pytest.mark.parametrize(
    "width, height, steps",
    [
        (424, 424, 2000),  # the rule's own capture: RUN_PIXELS is 2000 steps of it
        (497, 372, 1900),  # 184 884 pixels: 1947 steps, in hundreds
        (509, 509, 1400),  # 259 081 pixels: 1390
        (397, 298, MAX_SCENE_ITERS),  # smaller views: never past the cap
        (1000, 1000, MIN_SCENE_ITERS),  # 360 steps would be too few to fit anything
    ],
)
def test_capture_iters_spends_the_pixel_budget_in_hundreds_of_steps_within_bounds(width, height, steps):
    assert capture_iters(width * height, 66) == steps
    assert RUN_PIXELS == 2000 * 424 * 424


@pytest.mark.parametrize(
    "views, steps",
    [
        (FULL_RUN_VIEWS, 1400),  # 259 081 pixels a view: 1390 steps, in hundreds
        (96, 1200),  # gaussctrl_bear: 1158
        (190, MIN_SCENE_ITERS),  # 585: too few to fit anything
    ],
)
def test_past_the_full_run_views_the_pixels_shrink_in_proportion(views, steps):
    assert capture_pixels(views) == RUN_PIXELS * min(1.0, FULL_RUN_VIEWS / views)
    assert capture_iters(509 * 509, views) == steps


@pytest.mark.parametrize(
    "size, options, steps",
    [
        (424, lambda scene: DemoOptions(iters=77, scene=scene), 77),
        (128, lambda scene: DemoOptions(), EMBEDDED_ITERS),
        (509, lambda scene: DemoOptions(scene=scene), 1400),
    ],
)
def test_the_asked_iterations_and_the_embedded_scene_keep_their_own(tmp_path, size, options, steps):
    scene = _capture(tmp_path, size, 10)
    assert demo_training(scene, "images", options(scene)).iters == steps


@pytest.mark.parametrize(
    "points, cap",
    [
        (3_985, MIN_SCENE_GAUSSIANS),  # the statue: room enough under 30k
        (15_000, MIN_SCENE_GAUSSIANS),  # twice the points is the least cap
        (34_790, 70_000),  # gaussctrl_bear: 69 580, in thousands
        (80_000, MAX_SCENE_GAUSSIANS),
    ],
)
def test_capture_gaussians_leaves_room_to_double_the_sfm_points_within_bounds(points, cap):
    assert capture_gaussians(points) == cap


def test_demo_training_reads_the_view_size_and_the_sfm_points_and_says_why(tmp_path):
    scene = _capture(tmp_path, 509, 16_000, folder="images/sub")
    plan = demo_training(scene, "images", DemoOptions(scene=scene))
    assert (plan.iters, plan.max_gaussians) == (1400, 32_000)
    assert plan.why == (
        "training 1400 steps, at most 32,000 Gaussians (360 million pixels in all at 509x509 a view, "
        "1000-2000 steps; 16,000 SfM points, room to grow them 2x)"
    )
    plan = demo_training(scene, "images", DemoOptions(scene=scene, iters=300, max_gaussians=5000))
    assert (plan.iters, plan.max_gaussians) == (300, 5000)
    assert plan.why == "training 300 steps, at most 5,000 Gaussians (steps as asked; the cap as asked)"
    embedded = demo_training(scene, "images", DemoOptions())
    assert (embedded.iters, embedded.max_gaussians) == (EMBEDDED_ITERS, MIN_SCENE_GAUSSIANS)


def test_demo_training_of_many_photos_says_how_their_pixels_shrank(tmp_path):
    scene = _capture(tmp_path, 509, 16_000, views=96)
    plan = demo_training(scene, "images", DemoOptions(scene=scene))
    assert plan.iters == 1200
    assert plan.why == (
        "training 1200 steps, at most 32,000 Gaussians (300 million pixels in all, 80/96 of 360 for 96 photos, "
        "at 509x509 a view, 1000-2000 steps; 16,000 SfM points, room to grow them 2x)"
    )
