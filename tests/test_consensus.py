"""Multi-view consensus: flow-carried ID maps of neighbouring views vote on each view's labels;
the flow that a rough depth starts from; the depth priors."""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from dataset_tools.cameras import CameraPose, PinholeCamera
from hqmask.association.anchors import Anchor
from hqmask.consensus import multiview_consensus, vote
from hqmask.depth_prior import depth_from_anchors, depth_from_points
from hqmask.optical_flow import (
    consistent_flow,
    depth_flow,
    flow_between,
    geometric_flow,
    matching_colors,
    pull_along_plane,
    pull_labels,
)

SHIFT = 4  # pixels the scene moves left from one view to the next
FOCAL, DEPTH = 100.0, 10.0  # the plane stands DEPTH in front of cameras of focal FOCAL


def panning(n: int, size: int, step_px: float = SHIFT) -> list[CameraPose]:
    """Cameras looking along +z, each ``step_px`` pixels (on the plane at DEPTH) right of the last."""
    camera = PinholeCamera(size, size, FOCAL, FOCAL, size / 2, size / 2)
    step = step_px * DEPTH / FOCAL
    return [CameraPose(camera, np.concatenate([np.eye(3), [[-step * v], [0.0], [0.0]]], 1)) for v in range(n)]


def _views(n: int = 5, size: int = 128):
    """``n`` views of one textured plane seen through a camera panning right by SHIFT pixels a
    view; an object is the square [40, 80)^2 of the plane. Returns images, exact ID maps and
    the camera poses."""
    rng = np.random.default_rng(0)
    plane = ndimage.gaussian_filter(rng.random((size, size + SHIFT * n)), 2.0)
    plane = (255 * (plane - plane.min()) / np.ptp(plane)).astype(np.uint8)
    images, truth = [], []
    for v in range(n):
        crop = plane[:, SHIFT * v : SHIFT * v + size]
        images.append(np.repeat(crop[..., None], 3, axis=2))
        ids = np.zeros((size, size), np.uint8)
        ids[40:80, 40 - SHIFT * v : 80 - SHIFT * v] = 7
        truth.append(ids)
    return images, truth, panning(n, size)


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
    assert np.allclose(np.median(flow[..., 0]), -SHIFT, atol=0.25) and np.allclose(
        np.median(flow[..., 1]), 0, atol=0.25
    )
    carried = pull_labels(truth[3], flow)
    trusted = consistent_flow(flow, flow_between(images[3], images[2]), 1.0)
    inner = np.s_[8:-8, 8:-8]
    assert trusted[inner].mean() > 0.95
    assert (carried == truth[2])[inner][trusted[inner]].mean() > 0.99


def test_consensus_restores_a_missed_object_and_a_wandering_boundary():
    images, truth, views = _views()
    noisy = [t.copy() for t in truth]
    noisy[2][:] = 0  # the object missed in the middle view
    noisy[1][40:80, 36 - SHIFT : 45 - SHIFT] = 7  # its left edge 4 px too far out in another
    lone = [t.copy() for t in truth]
    lone[2][60:70, 10:20] = 7  # a blob only this view has: one witness cannot outvote it
    fixed = multiview_consensus(images, noisy, views, neighbours=4)
    inner = np.s_[8:-8, 8:-8]
    for v in (1, 2):
        assert (fixed[v] == truth[v])[inner].mean() > 0.99, v
    kept = multiview_consensus(images, lone, views, neighbours=1)
    assert (kept[2][60:70, 10:20] == 7).all()


def test_one_witness_fills_a_missed_object_but_does_not_erase_one():
    """The view's own background counts 0.9, its own object 1.5: one neighbour that sees the
    object fills it in where the view missed it, and one that misses it does not erase it."""
    images, truth, views = _views(2)
    missed = [truth[0], np.zeros_like(truth[1])]
    assert (multiview_consensus(images, missed, views, neighbours=1)[1] == truth[1])[8:-8, 8:-8].mean() > 0.99
    erased = [np.zeros_like(truth[0]), truth[1]]
    assert np.array_equal(multiview_consensus(images, erased, views, neighbours=1)[1], truth[1])


def test_a_neighbour_of_another_size_is_resized_to_witness():
    """Undistorted views of one capture differ in size by a few pixels."""
    images, truth, views = _views(3)
    noisy = [t.copy() for t in truth]
    noisy[1][:] = 0
    for v in (0, 2):  # both neighbours 4 px taller
        images[v] = np.concatenate([images[v], images[v][-4:]])
        noisy[v] = np.concatenate([noisy[v], noisy[v][-4:]])
        camera = views[v].camera
        views[v] = CameraPose(
            PinholeCamera(camera.width, camera.height + 4, FOCAL, FOCAL, camera.cx, camera.cy), views[v].cam_from_world
        )
    fixed = multiview_consensus(images, noisy, views, neighbours=2)
    assert fixed[1].shape == truth[1].shape
    assert (fixed[1] == truth[1])[8:-8, 8:-8].mean() > 0.99


def test_mutual_neighbours_share_their_flows(monkeypatch):
    """Each pair of mutual neighbours computes its two flows once, and the result is that of
    computing them afresh for each view: on 5 views that all neighbour each other, 20 flows
    instead of 40."""
    import hqmask.consensus as consensus

    images, truth, views = _views()
    noisy = [t.copy() for t in truth]
    noisy[2][:] = 0
    calls = []
    centers = np.stack([v.center for v in views])

    def counted(image, other, *args, **kwargs):
        calls.append(1)
        return geometric_flow(image, other, *args, **kwargs)

    def afresh(v: int) -> np.ndarray:
        near = [j for j in np.argsort(np.sum((centers - centers[v]) ** 2, -1), kind="stable") if j != v][:4]
        labels, weights = [noisy[v]], [np.where(noisy[v] > 0, 1.5, 0.9).astype(np.float32)]
        for j in near:
            to_j, from_j = flow_between(images[v], images[j]), flow_between(images[j], images[v])
            labels.append(pull_labels(noisy[j], to_j))
            weights.append(
                (consistent_flow(to_j, from_j, 2.0) & matching_colors(images[v], images[j], to_j, 10.0)).astype(
                    np.float32
                )
            )
        return vote(np.stack(labels), np.stack(weights))

    monkeypatch.setattr(consensus, "geometric_flow", counted)
    fixed = multiview_consensus(images, noisy, views, neighbours=4)
    assert len(calls) == 20
    assert all(np.array_equal(fixed[v], afresh(v)) for v in range(5))


def test_the_flow_a_depth_implies_is_the_cameras_parallax():
    """A plane at DEPTH seen from cameras 1 unit apart along x moves FOCAL / DEPTH pixels."""
    views = panning(2, 64, step_px=FOCAL / DEPTH)
    flow = depth_flow(views[0], views[1], np.full((64, 64), DEPTH, np.float32))
    assert np.allclose(flow[..., 0], -FOCAL / DEPTH, atol=1e-4) and np.allclose(flow[..., 1], 0, atol=1e-4)


def test_a_depth_lets_the_flow_follow_a_step_plain_flow_cannot():
    """A 40 px step on a fine texture: plain DIS misses it, the flow started from the depth
    finds it (to a pixel) and carries the object across."""
    images, truth, _ = _views(n=2, size=128)
    rng = np.random.default_rng(1)
    plane = ndimage.gaussian_filter(rng.random((128, 256)), 1.0)
    plane = (255 * (plane - plane.min()) / np.ptp(plane)).astype(np.uint8)
    step = 40
    images = [np.repeat(plane[:, s : s + 128, None], 3, axis=2) for s in (0, step)]
    views = panning(2, 128, step_px=step)
    depth = np.full((128, 128), DEPTH, np.float32)
    inner = np.s_[16:-16, 16:-56]
    plain = flow_between(images[0], images[1])
    started = geometric_flow(images[0], images[1], views[0], views[1], depth)
    assert np.abs(plain[inner][..., 0] + step).mean() > 5
    assert np.abs(started[inner][..., 0] + step).mean() < 1


def test_depth_priors_have_known_answers():
    camera = PinholeCamera(40, 30, 50.0, 50.0, 20.0, 15.0)
    view = CameraPose(camera, np.concatenate([np.eye(3), np.zeros((3, 1))], 1))
    ids = np.zeros((30, 40), np.uint8)
    ids[5:15, 5:15] = 3
    # one observation on the object at depth 2, two on the background at 8 and 9
    uv = np.array([[10.0, 10.0], [30.0, 5.0], [30.0, 25.0]])
    xyz = np.array([[(u - 20) / 50 * z, (v - 15) / 50 * z, z] for (u, v), z in zip(uv, (2.0, 8.0, 9.0))])
    depth = depth_from_points(view, uv, xyz, ids)
    assert (depth[ids == 3] == 2.0).all() and depth[2, 30] == 8.0 and depth[28, 30] == 9.0
    anchors = {3: Anchor(np.array([0.0, 0.0, 4.0]), 0.5, 0.3), 5: Anchor(np.array([1.0, 0.0, 7.0]), 0.5, 0.3)}
    depth = depth_from_anchors(view, ids, anchors)
    assert (depth[ids == 3] == 4.0).all() and depth[0, 0] == 7.0
    # object 5, missed in this view, stands where its anchor projects: a disk of 5 px radius
    # about (30, 15); the background lies as far as the farthest anchor, object 6
    anchors = {
        3: anchors[3],
        5: Anchor(np.array([1.0, 0.0, 5.0]), 0.5, 0.3),
        6: Anchor(np.array([-3.0, 0.0, 9.0]), 0.5, 0.3),
    }
    depth = depth_from_anchors(view, ids, anchors)
    assert depth[15, 30] == 5.0 and depth[15, 34] == 5.0 and depth[15, 37] == 9.0 and depth[28, 2] == 9.0
    assert (depth[ids == 3] == 4.0).all()
    assert depth_from_anchors(view, ids, {3: Anchor(np.array([0.0, 0.0, -1.0]), 0.5, 0.3)}) is None


def test_carrying_along_a_plane_agrees_with_the_flow_its_depth_implies():
    """Two cameras far apart and turned towards each other: the homography of a plane at a
    depth carries a label map where the per-pixel flow of that constant depth does."""
    camera = PinholeCamera(96, 64, 80.0, 80.0, 48.0, 32.0)
    a = CameraPose(camera, np.concatenate([np.eye(3), np.zeros((3, 1))], 1))
    turn = np.deg2rad(20)
    R = np.array([[np.cos(turn), 0, -np.sin(turn)], [0, 1, 0], [np.sin(turn), 0, np.cos(turn)]])
    center = np.array([2.0, 0.3, 0.5])
    b = CameraPose(camera, np.concatenate([R, (-R @ center)[:, None]], 1))
    labels = np.zeros((64, 96), np.uint8)
    labels[20:44, 30:70] = 5
    by_plane = pull_along_plane(labels, a, b, 6.0, (64, 96))
    by_flow = pull_labels(labels, depth_flow(a, b, np.full((64, 96), 6.0, np.float32)))
    assert (by_plane == 5).sum() > 200 and (by_plane != by_flow).mean() < 0.01
