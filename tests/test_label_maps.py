"""ID matching between label maps, and the box around a mask, against hand-computed answers."""

import numpy as np

from dataset_tools.image_files import colorize_labels
from dataset_tools.label_maps import mask_box, match_ids, matched_error, overlap


def test_matching_undoes_a_permutation():
    gt = np.array([[0, 1, 1], [2, 2, 3], [3, 3, 0]], np.uint8)
    lut = np.zeros(256, np.uint8)
    lut[[1, 2, 3]] = [9, 4, 200]
    pred = lut[gt]
    mapping = match_ids(overlap(pred, gt))
    assert mapping[9] == 1 and mapping[4] == 2 and mapping[200] == 3 and mapping[0] == 0
    assert matched_error(pred, gt) == 0.0


def test_matched_error_counts_merged_and_spurious_pixels():
    gt = np.array([[1, 1, 2, 2]], np.uint8)
    pred = np.array([[5, 5, 5, 6]], np.uint8)  # 5 matches 1 or 2 (2 pixels each); 6 matches the other
    assert matched_error(pred, gt) == 0.25


def test_palette_is_fixed_and_background_black():
    c = colorize_labels(np.array([[0, 1, 2]], np.uint8))
    assert (c[0, 0] == 0).all() and not (c[0, 1] == c[0, 2]).all()


def test_mask_box_widens_cuts_to_the_image_and_grows_within_it():
    mask = np.zeros((30, 40), bool)
    mask[2:6, 30:38] = True
    rows, cols = mask_box(mask, margin=3)
    assert (rows.start, rows.stop, cols.start, cols.stop) == (0, 9, 27, 40)  # cut at the top and right edges
    rows, cols = mask_box(mask, margin=3, min_side=20)
    assert (rows.start, rows.stop, cols.start, cols.stop) == (0, 20, 20, 40)  # grown, pushed back inside
    rows, cols = mask_box(mask, min_side=100)
    assert (rows.start, rows.stop, cols.start, cols.stop) == (0, 30, 0, 40)  # never past the image
