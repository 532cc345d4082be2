"""Mask corruption: deterministic, measured, growing with severity, sized with the image; the
proposer family's errors persist over runs of consecutive views."""

import json

import numpy as np
import pytest
from scipy import ndimage

from dataset_tools import InputError, load_scene
from dataset_tools.corruption import BlobModel, coarsen, corrupt_mask, corrupt_scene
from dataset_tools.corruption.proposer import ProposerModel, Run, corrupt_view, plan_runs
from dataset_tools.image_files import read_mask

QUIET = BlobModel(0.0, 6.0, 0, 0.0, 0.0, 0.0, 0.0, permute=False)


def test_same_seed_same_masks_other_seed_other_masks(scene_copy):
    a = corrupt_scene(scene_copy, "a", "medium", seed=3, progress=False)
    corrupt_scene(scene_copy, "b", "medium", seed=3, progress=False)
    c = corrupt_scene(scene_copy, "c", "medium", seed=4, progress=False)
    for stem in a["error_per_view"]:
        assert np.array_equal(read_mask(scene_copy / "a" / f"{stem}.png"), read_mask(scene_copy / "b" / f"{stem}.png"))
    assert a["error_per_view"] != c["error_per_view"]


@pytest.mark.parametrize("model", ["blobs", "proposer"])
def test_error_grows_with_severity(scene_copy, model):
    errors = [
        corrupt_scene(scene_copy, s, s, model=model, seed=0, progress=False)["mean_error"]
        for s in ("low", "medium", "high")
    ]
    assert 0 < errors[0] < errors[1] < errors[2]
    report = json.loads((scene_copy / "high" / "corruption.json").read_text())
    assert report["severity"] == "high" and report["model"] == model and len(report["error_per_view"]) == 8


def test_proposer_family_is_deterministic_by_seed(scene_copy):
    a = corrupt_scene(scene_copy, "a", "high", model="proposer", seed=3, progress=False)
    corrupt_scene(scene_copy, "b", "high", model="proposer", seed=3, progress=False)
    c = corrupt_scene(scene_copy, "c", "high", model="proposer", seed=4, progress=False)
    for stem in a["error_per_view"]:
        assert np.array_equal(read_mask(scene_copy / "a" / f"{stem}.png"), read_mask(scene_copy / "b" / f"{stem}.png"))
    assert a["error_per_view"] != c["error_per_view"]


def test_permutation_alone_costs_nothing_after_matching():
    gt = np.zeros((40, 40), np.uint8)
    gt[5:15, 5:15], gt[20:30, 20:35] = 1, 2
    noisy = corrupt_mask(gt, BlobModel(**{**QUIET.__dict__, "permute": True}), np.random.default_rng(0))
    assert not np.array_equal(noisy, gt)
    assert np.array_equal(noisy > 0, gt > 0)
    assert len(np.unique(noisy[gt == 1])) == 1 and len(np.unique(noisy[gt == 2])) == 1


@pytest.mark.parametrize("side", [512, 256])
def test_blob_sizes_straddle_the_paper_threshold_scaled_to_the_image(side):
    """At 512 x 512 small blobs stay under the paper's 500 px and large ones pass it; at
    256 x 256 the same blobs cover a quarter of the pixels, as a proposer's errors would."""
    threshold = 500 * (side / 512) ** 2
    gt = np.zeros((side, side), np.uint8)
    gt[:, side // 2 :] = 1
    rng = np.random.default_rng(0)
    small = corrupt_mask(gt, BlobModel(**{**QUIET.__dict__, "small_blobs": 30}), rng)
    assert blob_areas(gt, small).max() < threshold
    large = corrupt_mask(gt, BlobModel(**{**QUIET.__dict__, "large_blobs": 6.0}), rng)
    assert threshold < blob_areas(gt, large).max() < 3 * threshold


def blob_areas(gt, noisy):
    labels, n = ndimage.label(noisy != gt)
    return np.bincount(labels.ravel())[1:]


def test_coarse_masks_round_sharp_corners_but_keep_large_shapes():
    gt = np.zeros((128, 128), np.uint8)
    gt[20:100, 20:100] = 1  # a square: its corners are sharp
    gt[60:62, 0:128] = 2  # a 2-px line: finer than the low resolution
    out = coarsen(gt, 4)
    assert np.mean(out[gt == 1] == 1) > 0.95
    assert np.mean(out[gt == 2] == 2) < 0.5


def test_same_name_as_exact_masks_is_refused(scene_copy):
    with pytest.raises(InputError, match="which this command reads"):
        corrupt_scene(scene_copy, "gt_mask", progress=False)


def test_existing_output_is_kept_without_force(scene_copy):
    corrupt_scene(scene_copy, "noisy", "low", progress=False)
    before = read_mask(scene_copy / "noisy" / "0000.png")
    with pytest.raises(InputError, match="already exists"):
        corrupt_scene(scene_copy, "noisy", "high", progress=False)
    assert np.array_equal(read_mask(scene_copy / "noisy" / "0000.png"), before)
    corrupt_scene(scene_copy, "noisy", "high", progress=False, overwrite=True)
    assert load_scene(scene_copy, masks="noisy").has_masks


QUIET_PROPOSER = ProposerModel(
    p_parts=0, p_merge=0, p_miss=0, p_shadow=0, fragments=0, p_bleed=0, bleed_px=0, jitter_px=0
)


def two_boxes() -> np.ndarray:
    gt = np.zeros((64, 96), np.uint8)
    gt[10:40, 10:40], gt[10:40, 55:85] = 1, 2
    return gt


def test_a_run_holds_over_consecutive_views_and_nowhere_else():
    gt = two_boxes()
    runs = [Run("miss", 1, 2, 5), Run("parts", 2, 4, 6, angle=0.0, parts=3), Run("merge", 2, 0, 1)]
    out = [corrupt_view(gt, k, runs, QUIET_PROPOSER, np.random.default_rng(k)) for k in range(7)]
    seen_1 = [len(np.unique(o[gt == 1])) == 1 and o[20, 20] > 0 for o in out]
    assert seen_1 == [True, True, False, False, False, True, True]  # missed in views 2..4
    parts_2 = [len(np.unique(o[gt == 2])) for o in out]
    assert parts_2 == [1, 1, 1, 1, 3, 3, 1]  # three bands in views 4 and 5
    assert out[0][20, 20] == out[0][20, 70] and out[1][20, 20] != out[1][20, 70]  # merged in view 0 only


def test_shadow_fragments_and_bleeding_touch_only_the_background():
    gt = two_boxes()
    model = ProposerModel(p_parts=0, p_merge=0, p_miss=0, p_shadow=0, fragments=3, p_bleed=1.0, bleed_px=3, jitter_px=0)
    out = corrupt_view(gt, 0, [Run("shadow", 1, 0, 1)], model, np.random.default_rng(0))
    for label in (1, 2):
        assert len(np.unique(out[gt == label])) == 1  # objects keep their pixels
    grown = (out > 0) & (gt == 0)
    assert grown.sum() > 0 and len(np.unique(out)) > 3  # bled pixels, a shadow and fragments


def test_runs_are_planned_from_the_seed_and_last_at_most_their_share():
    model = ProposerModel(
        p_parts=1, p_merge=1, p_miss=1, p_shadow=1, fragments=0, p_bleed=0, bleed_px=0, jitter_px=0, run_share=0.25
    )
    runs = plan_runs([1, 2, 3], 40, model, np.random.default_rng(5))
    assert runs == plan_runs([1, 2, 3], 40, model, np.random.default_rng(5))
    assert len(runs) == 12 and all(1 <= r.stop - r.start <= 10 for r in runs)


def test_the_truth_of_a_scene_from_before_gt_mask_is_an_input_too(small_scene, tmp_path):
    """An old synthetic scene keeps its truth in ``object_mask/``: corrupting it into that folder
    is writing over what the command reads, refused as such even with ``overwrite``."""
    import shutil
    import warnings

    old = tmp_path / "old"
    shutil.copytree(small_scene.root, old, ignore=shutil.ignore_patterns("object_mask"))
    (old / "gt_mask").rename(old / "object_mask")
    with warnings.catch_warnings(), pytest.raises(InputError, match="which this command reads"):
        warnings.simplefilter("ignore")
        corrupt_scene(old, "object_mask", overwrite=True, progress=False)
