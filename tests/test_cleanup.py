"""Noise removal on hand-made label maps, and the connected-components kernel against scikit-image."""

import numpy as np
import pytest
from skimage import measure

from hqmask.cleanup import clean_mask, close_labels, remove_small_components
from hqmask.components import label_components


def same_partition(a, b):
    pairs = np.unique(a.astype(np.int64).ravel() * (b.max() + 1) + b.ravel())
    return len(pairs) == len(np.unique(a)) == len(np.unique(b))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_components_match_scikit_image(seed):
    rng = np.random.default_rng(seed)
    ids = rng.integers(0, 4, (60, 70)).astype(np.uint8)
    comp, n = label_components(ids)
    ref = measure.label(ids, background=-1, connectivity=2)
    assert n == ref.max() and same_partition(comp, ref)


def two_touching_objects():
    ids = np.zeros((80, 100), np.uint8)
    ids[10:70, 10:50] = 1
    ids[10:70, 50:90] = 2  # touches object 1 along column 50
    return ids


def test_small_speck_in_object_takes_the_object_label():
    ids = two_touching_objects()
    ids[30:35, 20:25] = 7  # 25 px speck inside object 1
    out = clean_mask(ids, min_area=100)
    assert np.array_equal(out, two_touching_objects())


def test_speck_in_background_becomes_background_and_holes_are_filled():
    ids = two_touching_objects()
    ids[0:4, 0:4] = 3  # speck surrounded by background
    ids[40:45, 60:66] = 0  # hole inside object 2
    out = clean_mask(ids, min_area=100)
    assert np.array_equal(out, two_touching_objects())


def test_components_over_min_area_change_only_by_closing():
    rng = np.random.default_rng(0)
    ids = two_touching_objects()
    noise = rng.uniform(size=ids.shape) < 0.02
    ids[noise] = rng.integers(0, 5, noise.sum())
    closed = close_labels(ids)
    out = remove_small_components(closed, 100)
    comp, n = label_components(closed)
    big = np.bincount(comp.ravel(), minlength=n)[comp] >= 100
    assert np.array_equal(out[big], closed[big])
    comp_out, n_out = label_components(out)
    assert np.bincount(comp_out.ravel(), minlength=n_out).min() >= 100


def test_closing_fills_gaps_within_an_object_but_never_bleeds():
    ids = np.zeros((20, 20), np.uint8)
    ids[5:15, 2:9] = 1
    ids[5:15, 10:17] = 1  # one-pixel gap at column 9 inside object 1
    assert (close_labels(ids)[6:14, 9] == 1).all()
    ids[5:15, 10:17] = 2  # now the gap separates two objects
    out = close_labels(ids)
    assert (out[:, 9] == 0).all()
    assert np.array_equal(out[ids > 0], ids[ids > 0])
