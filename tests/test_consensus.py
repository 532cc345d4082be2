"""Multi-view consensus: flow-carried ID maps of neighbouring views vote on each view's labels."""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from hqmask.consensus import multiview_consensus, vote
from hqmask.optical_flow import consistent_flow, flow_between, matching_colors, pull_labels

SHIFT = 4  # pixels the scene moves left from one view to the next


def _views(n: int = 5, size: int = 128):
    """``n`` views of one textured plane seen through a camera panning right by SHIFT pixels a
    view; an object is the square [40, 80)^2 of the plane. Returns images, exact ID maps and
    camera centres along x."""
    rng = np.random.default_rng(0)
    plane = ndimage.gaussian_filter(rng.random((size, size + SHIFT * n)), 2.0)
    plane = (255 * (plane - plane.min()) / np.ptp(plane)).astype(np.uint8)
    images, truth = [], []
    for v in range(n):
        crop = plane[:, SHIFT * v: SHIFT * v + size]
        images.append(np.repeat(crop[..., None], 3, axis=2))
        ids = np.zeros((size, size), np.uint8)
        ids[40:80, 40 - SHIFT * v: 80 - SHIFT * v] = 7
        truth.append(ids)
    centers = np.stack([[SHIFT * v, 0.0, 0.0] for v in range(n)])
    return images, truth, centers


def test_vote_takes_the_weighted_majority_and_the_own_label_on_ties():
    labels = np.array([[[1, 1, 1, 1]], [[2, 2, 3, 1]], [[2, 3, 3, 2]]], np.uint8)
    weights = np.array([[[1.5] * 4], [[1, 1, 1, 0]], [[1, 1, 1, 1]]], np.float32)
    # pixel 0: two witnesses for 2 (2.0) beat the own 1 (1.5); pixel 1: 1.5 against 1 and 1;
    # pixel 2: 3 with 2.0; pixel 3: 1 (1.5) against 2 (1.0), the other witness does not vote
    assert vote(labels, weights).tolist() == [[2, 1, 3, 1]]
    assert vote(labels[:2], np.stack([weights[0], weights[0]])).tolist() == [[1, 1, 1, 1]]  # a tie keeps the own


def test_flow_carries_labels_from_the_other_view():
    images, truth, _ = _views()
    flow = flow_between(images[2], images[3])
    assert np.allclose(np.median(flow[..., 0]), -SHIFT, atol=0.25) and np.allclose(np.median(flow[..., 1]), 0, atol=0.25)
    carried = pull_labels(truth[3], flow)
    trusted = consistent_flow(flow, flow_between(images[3], images[2]), 1.0)
    inner = np.s_[8:-8, 8:-8]
    assert trusted[inner].mean() > 0.95
    assert (carried == truth[2])[inner][trusted[inner]].mean() > 0.99


def test_consensus_restores_a_missed_object_and_a_wandering_boundary():
    images, truth, centers = _views()
    noisy = [t.copy() for t in truth]
    noisy[2][:] = 0  # the object missed in the middle view
    noisy[1][40:80, 36 - SHIFT: 45 - SHIFT] = 7  # its left edge 4 px too far out in another
    lone = [t.copy() for t in truth]
    lone[2][60:70, 10:20] = 7  # a blob only this view has: one witness cannot outvote it
    fixed = multiview_consensus(images, noisy, centers, neighbours=4)
    inner = np.s_[8:-8, 8:-8]
    for v in (1, 2):
        assert (fixed[v] == truth[v])[inner].mean() > 0.99, v
    kept = multiview_consensus(images, lone, centers, neighbours=1)
    assert (kept[2][60:70, 10:20] == 7).all()


def test_a_neighbour_of_another_size_is_resized_to_witness():
    """Undistorted views of one capture differ in size by a few pixels."""
    images, truth, centers = _views(3)
    noisy = [t.copy() for t in truth]
    noisy[1][:] = 0
    for v in (0, 2):  # both neighbours 4 px taller
        images[v] = np.concatenate([images[v], images[v][-4:]])
        noisy[v] = np.concatenate([noisy[v], noisy[v][-4:]])
    fixed = multiview_consensus(images, noisy, centers, neighbours=2)
    assert fixed[1].shape == truth[1].shape
    assert (fixed[1] == truth[1])[8:-8, 8:-8].mean() > 0.99


def test_mutual_neighbours_share_their_flows(monkeypatch):
    """Each pair of mutual neighbours computes its two flows once, and the result is that of
    computing them afresh for each view: on 5 views that all neighbour each other, 20 flows
    instead of 40."""
    import hqmask.consensus as consensus

    images, truth, centers = _views()
    noisy = [t.copy() for t in truth]
    noisy[2][:] = 0
    calls = []

    def counted(image, other):
        calls.append(1)
        return flow_between(image, other)

    def afresh(v: int) -> np.ndarray:
        H, W = truth[v].shape
        near = [j for j in np.argsort(np.sum((centers - centers[v]) ** 2, -1), kind="stable") if j != v][:4]
        labels, weights = [noisy[v]], [np.full((H, W), 1.5, np.float32)]
        for j in near:
            to_j, from_j = flow_between(images[v], images[j]), flow_between(images[j], images[v])
            labels.append(pull_labels(noisy[j], to_j))
            weights.append((consistent_flow(to_j, from_j, 2.0)
                            & matching_colors(images[v], images[j], to_j, 10.0)).astype(np.float32))
        return vote(np.stack(labels), np.stack(weights))

    monkeypatch.setattr(consensus, "flow_between", counted)
    fixed = multiview_consensus(images, noisy, centers, neighbours=4)
    assert len(calls) == 20
    assert all(np.array_equal(fixed[v], afresh(v)) for v in range(5))
