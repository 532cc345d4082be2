"""Noise removal on hand-made label maps, and the connected-components kernel against scikit-image."""

import numpy as np
import pytest
from skimage import measure

from hqmask.cleanup import clean_mask, close_labels, default_min_area, remove_small_components
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


def test_speck_of_an_object_in_background_becomes_background_and_holes_are_filled():
    ids = two_touching_objects()
    ids[0:4, 0:4] = 2  # a speck of object 2 far from it, surrounded by background
    ids[40:45, 60:66] = 0  # hole inside object 2
    out = clean_mask(ids, min_area=100)
    assert np.array_equal(out, two_touching_objects())


def test_a_small_object_alone_survives_and_a_small_speck_inside_an_object_does_not():
    """300 px under a 500 px threshold: alone in the background it is an object (the only
    component of its ID); cut out of another object it is a speck of that object, unless
    other views confirm its ID; with keep_objects=False (the paper's rule) both go."""
    ids = np.zeros((100, 120), np.uint8)
    ids[10:90, 10:60] = 1
    ids[40:55, 20:40] = 2  # 300 px inside object 1
    ids[40:55, 80:100] = 3  # 300 px alone in the background
    out = clean_mask(ids, min_area=500)
    assert (out[40:55, 20:40] == 1).all() and (out[40:55, 80:100] == 3).all()
    assert (clean_mask(ids, min_area=500, keep=frozenset({2}))[40:55, 20:40] == 2).all()
    paper = clean_mask(ids, min_area=500, keep_objects=False)
    assert (paper[40:55, 20:40] == 1).all() and (paper[40:55, 80:100] == 0).all()


def test_the_default_threshold_is_the_papers_share_of_the_image():
    assert default_min_area((756, 1008)) == 500
    assert default_min_area((512, 512)) == 172 and default_min_area((192, 192)) == 24
    assert default_min_area((8, 8)) == 1


def test_components_over_min_area_change_only_by_closing():
    rng = np.random.default_rng(0)
    ids = two_touching_objects()
    noise = rng.uniform(size=ids.shape) < 0.02
    ids[noise] = rng.integers(0, 5, noise.sum())
    closed = close_labels(ids)
    out = remove_small_components(closed, 100, keep_objects=False)
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
