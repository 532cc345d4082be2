"""Mask corruption: deterministic, measured, and growing with severity."""

import json

import numpy as np
import pytest
from scipy import ndimage

from dataset_tools import InputError, load_scene
from dataset_tools.corrupt import CorruptionModel, coarsen, corrupt_mask, corrupt_scene
from dataset_tools.image_files import read_mask

QUIET = CorruptionModel(0.0, 6.0, 0, 0.0, 0.0, 0.0, 0.0, permute=False)


def test_same_seed_same_masks_other_seed_other_masks(scene_copy):
    a = corrupt_scene(scene_copy, "a", "medium", seed=3, progress=False)
    corrupt_scene(scene_copy, "b", "medium", seed=3, progress=False)
    c = corrupt_scene(scene_copy, "c", "medium", seed=4, progress=False)
    for stem in a["error_per_view"]:
        assert np.array_equal(read_mask(scene_copy / "a" / f"{stem}.png"), read_mask(scene_copy / "b" / f"{stem}.png"))
    assert a["error_per_view"] != c["error_per_view"]


def test_error_grows_with_severity(scene_copy):
    errors = [corrupt_scene(scene_copy, s, s, seed=0, progress=False)["mean_error"] for s in ("low", "medium", "high")]
    assert 0 < errors[0] < errors[1] < errors[2]
    report = json.loads((scene_copy / "high" / "corruption.json").read_text())
    assert report["severity"] == "high" and len(report["error_per_view"]) == 8


def test_permutation_alone_costs_nothing_after_matching():
    gt = np.zeros((40, 40), np.uint8)
    gt[5:15, 5:15], gt[20:30, 20:35] = 1, 2
    noisy = corrupt_mask(gt, CorruptionModel(**{**QUIET.__dict__, "permute": True}), np.random.default_rng(0))
    assert not np.array_equal(noisy, gt)
    assert np.array_equal(noisy > 0, gt > 0)
    assert len(np.unique(noisy[gt == 1])) == 1 and len(np.unique(noisy[gt == 2])) == 1


def test_blob_sizes_straddle_the_500_px_threshold():
    gt = np.zeros((256, 256), np.uint8)
    gt[:, 128:] = 1
    rng = np.random.default_rng(0)
    small = corrupt_mask(gt, CorruptionModel(**{**QUIET.__dict__, "small_blobs": 30}), rng)
    areas = blob_areas(gt, small)
    assert areas.max() < 500
    large = corrupt_mask(gt, CorruptionModel(**{**QUIET.__dict__, "large_blobs": 6.0}), rng)
    assert blob_areas(gt, large).max() > 500


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
    with pytest.raises(InputError, match="overwrite the exact masks"):
        corrupt_scene(scene_copy, "object_mask", progress=False)


def test_existing_output_is_kept_without_force(scene_copy):
    corrupt_scene(scene_copy, "noisy", "low", progress=False)
    before = read_mask(scene_copy / "noisy" / "0000.png")
    with pytest.raises(InputError, match="already exists"):
        corrupt_scene(scene_copy, "noisy", "high", progress=False)
    assert np.array_equal(read_mask(scene_copy / "noisy" / "0000.png"), before)
    corrupt_scene(scene_copy, "noisy", "high", progress=False, overwrite=True)
    assert load_scene(scene_copy, masks="noisy").has_masks
