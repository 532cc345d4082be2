"""The 3D label regularisations of ``gsseg segment``: weak evidence, neighbour smoothing and
interior filling, on hand-made point sets with known answers."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from scipy.spatial import cKDTree

from gsseg.render.contributions import Contributions
from gsseg.run.folder import RunFolder
from gsseg.segment.reassign import Segmentation
from gsseg.segment.regularize import DIRECTIONS, _enclosed, fill_interiors, smooth_weak_labels, weak_evidence


def _segmentation(labels: np.ndarray) -> Segmentation:
    return Segmentation.of_labels(labels, "prior", gamma_p=0.2)


def _sphere(n: int, radius: float, rng: np.random.Generator) -> np.ndarray:
    v = rng.normal(size=(n, 3))
    return radius * v / np.linalg.norm(v, axis=1, keepdims=True)


def test_weak_evidence_flags_small_totals_and_near_ties():
    # Columns: a clear winner, a near tie (0.55 / 0.45), a clear winner seen 100x less than the median.
    weights = torch.tensor([[9.0, 5.5, 0.09, 8.0], [1.0, 4.5, 0.01, 2.0]])
    weak = weak_evidence(Contributions(labels=np.array([0, 1], np.uint8), weights=weights))
    np.testing.assert_array_equal(weak, [False, True, True, False])


def test_smoothing_relabels_weak_gaussians_by_opacity_weighted_neighbours_only():
    # A weak Gaussian at the origin; 3 opaque neighbours of label 1, 5 faint ones of label 2.
    rng = np.random.default_rng(0)
    means = np.concatenate([[[0.0, 0, 0]], 0.1 * _sphere(8, 1.0, rng)])
    labels = np.array([0, 1, 1, 1, 2, 2, 2, 2, 2])
    opacities = np.array([0.5, 0.9, 0.9, 0.9, 0.1, 0.1, 0.1, 0.1, 0.1])
    weak = np.zeros(9, bool)
    weak[0] = True
    out = smooth_weak_labels(_segmentation(labels), means, opacities, weak, k=8)
    np.testing.assert_array_equal(out.labels, [1, *labels[1:]])  # strong labels never change
    assert out.selections[out.objects.tolist().index(1)].sum() == 4 and out.smooth == 8


def test_fill_takes_the_interior_and_the_rim_but_not_the_outside_despite_floaters():
    """A hollow sphere of object 1 (radius 1) with a few far floaters also labelled 1: the
    background Gaussians inside it and on its surface join it; those beside it stay
    background (a floater must not stretch the object's extent over its surroundings)."""
    rng = np.random.default_rng(1)
    shell = _sphere(3000, 1.0, rng)
    interior = _sphere(200, 1.0, rng) * rng.uniform(0.0, 0.7, (200, 1))
    rim = _sphere(30, 1.0, rng)
    outside = _sphere(300, 1.0, rng) * rng.uniform(1.4, 2.0, (300, 1))
    floaters = np.array([[8.0, 8.0, 8.0], [-8.0, -8.0, -8.0], [8.0, -8.0, 0.0]])
    means = np.concatenate([shell, floaters, interior, rim, outside])
    labels = np.concatenate([np.ones(len(shell) + len(floaters)), np.zeros(len(interior) + len(rim) + len(outside))])
    filled = fill_interiors(_segmentation(labels), means)
    out = filled.labels
    start = len(shell) + len(floaters)
    assert (out[start : start + len(interior)] == 1).all()
    assert (out[start + len(interior) : start + len(interior) + len(rim)] == 1).all()
    assert (out[-len(outside) :] == 0).all()


def test_the_regularisation_applied_is_saved_with_the_labels(tmp_path):
    labels = np.array([0, 1, 1, 2])
    seg = fill_interiors(
        smooth_weak_labels(_segmentation(labels), np.eye(4, 3), np.ones(4), np.zeros(4, bool), k=4), np.eye(4, 3)
    )
    RunFolder(tmp_path).write_labels(seg)
    loaded = RunFolder(tmp_path).read_labels()
    assert (loaded.smooth, loaded.fill) == (4, True)
    np.testing.assert_array_equal(loaded.selections, seg.selections)


def test_fill_never_takes_another_objects_gaussians():
    """Object 2 inside a hollow sphere of object 1 (a statue inside the ring of trees around
    it) keeps its label; the background beside it inside the sphere joins object 1."""
    rng = np.random.default_rng(2)
    shell = _sphere(3000, 1.0, rng)
    inner = _sphere(300, 0.2, rng)
    loose = _sphere(50, 1.0, rng) * 0.6
    means = np.concatenate([shell, inner, loose])
    labels = np.concatenate([np.ones(len(shell)), np.full(len(inner), 2), np.zeros(len(loose))])
    out = fill_interiors(_segmentation(labels), means).labels
    assert (out[len(shell) : len(shell) + len(inner)] == 2).all()
    assert (out[len(shell) + len(inner) :] == 1).mean() > 0.9


@pytest.mark.parametrize("share", [0.5, 0.85, 1.0])
def test_enclosed_points_with_early_exits_match_every_probe_marched(share):
    """The early exits change no answer: every point against all 14 x 8 probes at once."""
    rng = np.random.default_rng(3)
    shell = _sphere(3000, 1.0, rng) * rng.uniform(0.9, 1.0, (3000, 1))
    shell = shell[shell[:, 2] < 0.6]  # an open top: points inside see out along some directions
    points = rng.uniform(-1.3, 1.3, (4000, 3))
    tree, step, steps = cKDTree(shell), 0.25, 8
    ts = step * np.arange(1, steps + 1)
    probes = points[:, None, None, :] + ts[None, None, :, None] * DIRECTIONS[None, :, None, :]
    distance, _ = tree.query(probes.reshape(-1, 3), distance_upper_bound=step)
    expected = np.isfinite(distance).reshape(len(points), len(DIRECTIONS), steps).any(2).mean(1) >= share
    assert 0 < expected.sum() < len(points)
    np.testing.assert_array_equal(_enclosed(points, tree, step, steps, share), expected)
