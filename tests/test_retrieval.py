"""Retrieval matching (:mod:`dataset_tools.sfm.retrieval`): VLAD vectors from a scene's own
vocabulary find the photos that share content, whatever the photos' order."""

from __future__ import annotations

import numpy as np

from dataset_tools.sfm.retrieval import root_sift, similar_pairs, vlad, vocabulary


def _photos(rng: np.random.Generator, places: int, per_place: int) -> tuple[list[np.ndarray], np.ndarray]:
    """Photos of ``places`` places, ``per_place`` each, shuffled: each photo holds most of its
    place's 300 SIFT-like descriptors (with noise) and some of its own. Returns the photos'
    descriptors and each photo's place."""
    scenes = [rng.integers(0, 256, (300, 128)) for _ in range(places)]
    place = rng.permutation(np.repeat(np.arange(places), per_place))
    photos = []
    for p in place:
        seen = scenes[p][rng.random(300) < 0.7]
        noise = rng.normal(0, 6, seen.shape)
        own = rng.integers(0, 256, (60, 128))
        photos.append(np.clip(np.concatenate([seen + noise, own]), 0, 255).astype(np.uint8))
    return photos, place


def test_root_sift_makes_euclidean_distance_a_hellinger_kernel():
    x = np.random.default_rng(0).integers(0, 256, (5, 128)).astype(np.uint8)
    r = root_sift(x)
    np.testing.assert_allclose(np.linalg.norm(r, axis=1), 1.0, rtol=1e-5)
    l1 = x / x.sum(1, keepdims=True)
    np.testing.assert_allclose(r @ r.T, np.sqrt(l1) @ np.sqrt(l1).T, rtol=1e-5)


def test_each_photo_is_matched_with_the_photos_of_its_place():
    """6 places, 5 shuffled photos each: every photo's 4 most alike are the other 4 of its place."""
    photos, place = _photos(np.random.default_rng(1), places=6, per_place=5)
    vectors = vlad(photos, vocabulary(photos, words=16))
    np.testing.assert_allclose(np.linalg.norm(vectors, axis=1), 1.0, rtol=1e-5)
    pairs = similar_pairs(vectors, neighbours=4)
    assert all(place[i] == place[j] for i, j in pairs)
    assert len(pairs) == 6 * 10  # every pair within a place, none across


def test_similar_pairs_are_the_nearest_of_each_photo_either_way_and_never_itself():
    angles = np.array([0.0, 0.1, 0.3, 2.0, 2.05, 4.0])
    vectors = np.stack([np.cos(angles), np.sin(angles)], 1)
    assert similar_pairs(vectors, neighbours=1) == [(0, 1), (1, 2), (3, 4), (4, 5)]
    assert similar_pairs(vectors[:1], neighbours=3) == []
    assert len(similar_pairs(vectors, neighbours=10)) == 15  # at most every pair
