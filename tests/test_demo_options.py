"""The demo's training sized to the capture: known answers of the rule and what it prints."""

import cv2
import numpy as np
import pytest

from pipeline.demo import demo_training
from pipeline.demo_options import (
    EMBEDDED_ITERS,
    MAX_SCENE_ITERS,
    MIN_SCENE_ITERS,
    RUN_PIXELS,
    DemoOptions,
    capture_iters,
)


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
    assert capture_iters(width * height) == steps
    assert RUN_PIXELS == 2000 * 424 * 424


@pytest.mark.parametrize(
    "size, options, steps",
    [
        (424, lambda scene: DemoOptions(iters=77, scene=scene), 77),
        (128, lambda scene: DemoOptions(), EMBEDDED_ITERS),
        (509, lambda scene: DemoOptions(scene=scene), 1400),
    ],
)
def test_the_asked_iterations_and_the_embedded_scene_keep_their_own(tmp_path, size, options, steps):
    (tmp_path / "images").mkdir()
    cv2.imwrite(str(tmp_path / "images" / "a.png"), np.zeros((size, size, 3), np.uint8))
    assert demo_training(tmp_path, "images", options(tmp_path))[0] == steps


def test_demo_training_reads_the_view_size_and_says_why(tmp_path):
    (tmp_path / "images" / "sub").mkdir(parents=True)
    cv2.imwrite(str(tmp_path / "images" / "sub" / "a.png"), np.zeros((509, 509, 3), np.uint8))
    iters, why = demo_training(tmp_path, "images", DemoOptions(scene=tmp_path))
    assert iters == 1400
    assert why == (
        "training 1400 steps, at most 30,000 Gaussians (360 million pixels in all at 509x509 a view, 1000-2000 steps)"
    )
    iters, why = demo_training(tmp_path, "images", DemoOptions(scene=tmp_path, iters=300, max_gaussians=5000))
    assert (iters, why) == (300, "training 300 steps, at most 5,000 Gaussians (as asked)")
