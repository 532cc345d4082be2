"""Ground truth for edits of synthetic scenes, and the edit metrics on hand-made images."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from dataset_tools import InputError, load_scene
from dataset_tools.synth.edit_truth import edit_truth, read_edit_truth, scene_layout, write_edit_truth
from dataset_tools.synth.generator import render_view
from eval.metrics import extraction_scores, region_box, removal_scores, ssim, ssim_map


def boundary_band(mask: np.ndarray, width: int = 1) -> np.ndarray:
    """Pixels within ``width`` of the mask's edge (supersampled colour mixes both sides there)."""
    kernel = np.ones((2 * width + 1, 2 * width + 1), np.uint8)
    m = mask.astype(np.uint8)
    return (cv2.dilate(m, kernel) - cv2.erode(m, kernel)) > 0


def test_without_an_object_the_view_changes_only_where_the_object_was(small_scene):
    layout = scene_layout(small_scene.root)
    scene = load_scene(small_scene.root)
    view = scene.split("test")[0]
    full_ids = view.load_mask()
    obj = int(np.bincount(full_ids.ravel())[1:].argmax()) + 1  # the largest object in this view
    truth = edit_truth(layout, obj, view, seers=[])
    image = view.load_image()
    elsewhere = (full_ids != obj) & ~boundary_band(full_ids == obj)
    assert np.array_equal(truth.without[elsewhere], image[elsewhere])
    assert (truth.without[full_ids == obj] != image[full_ids == obj]).any()
    # alone: white outside its whole silhouette, which covers every pixel it shows in the scene
    assert (truth.silhouette >= (full_ids == obj)).all()
    outside = ~truth.silhouette & ~boundary_band(truth.silhouette)
    assert (truth.alone[outside] == 255).all()
    assert not truth.seen.any() and not truth.silhouette_seen.any()  # no training view given: nothing is seen


def test_seen_marks_background_the_training_views_observe(small_scene):
    layout = scene_layout(small_scene.root)
    scene = load_scene(small_scene.root)
    view = scene.split("test")[0]
    full_ids = view.load_mask()
    obj = int(np.bincount(full_ids.ravel())[1:].argmax()) + 1
    seers = [(v, render_view(layout, v.camera, v.cam_from_world, 1)[2]) for v in scene.split("train")]
    truth = edit_truth(layout, obj, view, seers)
    assert truth.seen.any() and (truth.seen <= (full_ids == obj)).all()


def test_silhouette_seen_holds_what_a_training_view_shows_of_the_object(small_scene):
    """Scored from a training view itself, every pixel of the object that view shows is seen
    (it is its own seer), and nothing outside the silhouette is."""
    layout = scene_layout(small_scene.root)
    scene = load_scene(small_scene.root)
    view = scene.split("train")[0]
    full_ids = view.load_mask()
    obj = int(np.bincount(full_ids.ravel())[1:].argmax()) + 1
    truth = edit_truth(layout, obj, view, [(view, render_view(layout, view.camera, view.cam_from_world, 1)[2])])
    shown = (full_ids == obj) & ~boundary_band(full_ids == obj)
    assert truth.silhouette_seen[shown].all() and (truth.silhouette_seen <= truth.silhouette).all()


def test_written_truth_reads_back_and_unknown_objects_are_refused(scene_copy):
    out = write_edit_truth(scene_copy, progress=False)
    view = load_scene(scene_copy).split("test")[0]
    truth = read_edit_truth(scene_copy, 1, view.stem)
    assert truth is not None and truth.without.shape == view.load_image().shape
    assert read_edit_truth(scene_copy, 99, view.stem) is None and (out / "1" / "seen").is_dir()
    with pytest.raises(InputError, match="not in this scene"):
        edit_truth(scene_layout(scene_copy), 99, view, [])


def test_removal_scores_have_known_answers():
    truth = np.full((10, 10, 3), 100, np.uint8)
    removed = truth.copy()
    region = np.zeros((10, 10), bool)
    region[2:6, 2:6] = True
    removed[2:4, 2:6] = 110  # half the region off by 10 grey levels
    scores = removal_scores(removed, truth, region, seen=region)
    assert scores["psnr_region"] == pytest.approx(10 * np.log10(255**2 / 50))
    assert scores["psnr"] == pytest.approx(10 * np.log10(255**2 / (8 * 100 / 100)))
    assert removal_scores(truth, truth, region, region)["psnr_region"] == float("inf")
    assert removal_scores(truth, truth, region, ~region)["psnr_seen"] is None


def test_removal_ssim_and_lpips_are_taken_over_the_region():
    rng = np.random.default_rng(0)
    truth = rng.integers(0, 256, (80, 100, 3)).astype(np.uint8)
    region = np.zeros((80, 100), bool)
    region[30:40, 60:75] = True
    removed = truth.copy()
    removed[region] = 128  # a flat smudge where the object was
    crops = []

    def distance(pred: np.ndarray, target: np.ndarray) -> float:
        crops.append(pred.shape)
        return float(np.abs(pred.astype(float) - target).mean())

    scores = removal_scores(removed, truth, region, region, lpips=distance)
    similarity = ssim_map(removed, truth)
    assert scores["ssim"] == pytest.approx(ssim(removed, truth)) == pytest.approx(similarity.mean())
    assert scores["ssim_region"] == pytest.approx(similarity[region].mean())
    assert scores["ssim_region"] < 0.5 < scores["ssim"]
    assert similarity[:15].min() == pytest.approx(1.0)  # 11x11 windows away from the smudge see no change
    # LPIPS over the region's box widened by 8 px, then to 64 px a side: rows 3..67, columns 36..100
    assert crops == [(64, 64, 3)]
    box = region_box(region)
    assert (box[0].start, box[0].stop, box[1].start, box[1].stop) == (3, 67, 36, 100)
    assert scores["lpips_region"] == pytest.approx(np.abs(removed[box].astype(float) - truth[box]).mean())
    assert "lpips_region" not in removal_scores(removed, truth, region, region)
    assert removal_scores(removed, truth, np.zeros_like(region), region)["ssim_region"] is None


def test_extraction_scores_have_known_answers():
    silhouette = np.zeros((20, 20), bool)
    silhouette[5:15, 5:15] = True
    alpha = silhouette.astype(float)
    white = np.full((20, 20, 3), 255, np.uint8)
    perfect = extraction_scores(alpha, white, white, silhouette)
    assert perfect["iou"] == 1.0 and perfect["leak"] == 0.0 and perfect["psnr_inside"] == float("inf")
    smeared = alpha.copy()
    smeared[16:18, 5:15] = 0.4  # a faint floor smear 2 and 3 px below: only the row 3 px out is a leak
    s = extraction_scores(smeared, white, white, silhouette)
    assert s["leak"] == pytest.approx(4 / (100 + 8)) and s["iou"] == 1.0
    seen = silhouette.copy()
    seen[13:15] = False  # its bottom 2 rows never seen
    partial = alpha.copy()
    partial[13:15] = 0.0  # and not extracted
    s = extraction_scores(partial, white, white, silhouette, seen)
    assert s["iou"] == pytest.approx(0.8) and s["iou_seen"] == 1.0
    partial[0:2, 5:15] = 1.0  # 20 px outside the silhouette count against it either way
    s = extraction_scores(partial, white, white, silhouette, seen)
    assert s["iou"] == pytest.approx(80 / 120) and s["iou_seen"] == pytest.approx(80 / 100)
