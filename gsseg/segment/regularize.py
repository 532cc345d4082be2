"""Labels made consistent in 3D after reassignment.

The masks' vote decides each Gaussian from the pixels it reaches. Where that evidence is
weak, a Gaussian is labelled by chance, and those chance labels are what an edit leaves
behind: the rim of a removed object (Gaussians along its silhouette split their weight
between it and what lies behind), and its interior (Gaussians no view sees). Two rules, as
Gaussian Grouping regularises identities in 3D:

- :func:`smooth_weak_labels`: a Gaussian with weak evidence (a small share of the median
  contribution, or a near tie between its two best labels) takes the opacity-weighted label
  majority of its ``k`` nearest Gaussians;
- :func:`fill_interiors`: a Gaussian that an object's Gaussians enclose from most directions
  (at least ``share`` of 14 directions meet one of them within the object's size) joins it.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import torch
from scipy.spatial import cKDTree

from gsseg.render.contributions import Contributions
from gsseg.segment.reassign import Segmentation, normalize

DIRECTIONS = np.array(
    [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]]
    + [[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)],
    float,
)
DIRECTIONS /= np.linalg.norm(DIRECTIONS, axis=1, keepdims=True)
VOTE_CHUNK = 1 << 16  # weak Gaussians voted on at a time: (VOTE_CHUNK, 256) float64, 128 MiB


def weak_evidence(contributions: Contributions, *, min_share: float = 0.05, margin: float = 0.2) -> np.ndarray:
    """(N,) bool: Gaussians whose total contribution is under ``min_share`` of the median over
    the observed ones, or whose two best label shares lie within ``margin`` of each other."""
    weights = contributions.weights
    total = weights.sum(0)
    observed = total > 0
    median = float(total[observed].median()) if observed.any() else 0.0
    share, _ = normalize(weights)
    top = torch.topk(share, min(2, len(share)), dim=0).values if len(share) else torch.zeros(1, weights.shape[1])
    gap = top[0] - (top[1] if len(top) > 1 else 0)
    return ((total < min_share * median) | (gap < margin)).numpy()


def smooth_weak_labels(
    segmentation: Segmentation, means: np.ndarray, opacities: np.ndarray, weak: np.ndarray, k: int = 16
) -> Segmentation:
    """Weak Gaussians (``weak`` (N,) bool) take the opacity-weighted label majority of their
    ``k`` nearest Gaussians with strong evidence (N, 3 ``means``; (N,) ``opacities``). Labels
    of strong Gaussians never change."""
    strong = np.flatnonzero(~weak)
    targets = np.flatnonzero(weak)
    if not len(strong) or not len(targets):
        return replace(segmentation, smooth=k)
    _, nearest = cKDTree(means[strong]).query(means[targets], k=min(k, len(strong)), workers=-1)
    nearest = strong[np.atleast_2d(nearest.T).T]  # (T, k) indices into all Gaussians
    labels = segmentation.labels.copy()
    for start in range(0, len(targets), VOTE_CHUNK):  # (chunk, 256) votes at a time
        near = nearest[start : start + VOTE_CHUNK]
        rows = np.repeat(np.arange(len(near)), near.shape[1])
        votes = np.bincount(rows * 256 + labels[near].ravel(), opacities[near].ravel(), minlength=len(near) * 256)
        labels[targets[start : start + VOTE_CHUNK]] = votes.reshape(len(near), 256).argmax(1)
    return segmentation.relabelled(labels, smooth=k)


def fill_interiors(
    segmentation: Segmentation, means: np.ndarray, share: float = 0.85, steps: int = 8, extent_quantile: float = 0.01
) -> Segmentation:
    """Background Gaussians that one object's Gaussians enclose from at least ``share`` of the
    14 directions join that object (interiors no view sees, rims along its surface). Another
    object's Gaussians are never taken: a statue stands inside the ring of trees and façades
    around it, which is no hollow of theirs.

    The object's extent is the box between the ``extent_quantile`` and 1 - ``extent_quantile``
    quantiles of its Gaussians' positions, so that a few stray Gaussians given its label far
    away do not stretch it over its surroundings; its size is that box's diagonal. A Gaussian
    within one step (size / ``steps``) of the box is tested: a direction meets the object
    when a point along it, marched in ``steps`` steps up to the size, lies within one step of
    one of the object's Gaussians."""
    labels = segmentation.labels.copy()
    for obj in segmentation.objects:
        own = labels == obj
        if own.sum() < 8:
            continue
        lo, hi = np.quantile(means[own], [extent_quantile, 1 - extent_quantile], axis=0)
        size = float(np.linalg.norm(hi - lo))
        step = size / steps
        inside_box = np.all((means >= lo - step) & (means <= hi + step), axis=1) & (labels == 0)
        candidates = np.flatnonzero(inside_box)
        if not len(candidates) or size == 0:
            continue
        enclosed = _enclosed(means[candidates], cKDTree(means[own]), step, steps, share)
        labels[candidates[enclosed]] = obj
    return segmentation.relabelled(labels, fill=True)


def _enclosed(points: np.ndarray, tree: cKDTree, step: float, steps: int, share: float) -> np.ndarray:
    """(P,) bool: which of the (P, 3) ``points`` meet the object held in ``tree`` along at least
    ``share`` of the :data:`DIRECTIONS`; a direction meets it when one of ``steps`` points
    marched along it, ``step`` apart, lies within ``step`` of one of its Gaussians. A point
    drops out as soon as the directions left cannot bring it to ``share``, and a direction as
    soon as it meets the object, so that most of the queries go to the points that may be
    enclosed."""
    met = np.zeros(len(points), np.int64)
    alive = np.arange(len(points))
    for d, direction in enumerate(DIRECTIONS):
        marching = alive
        for k in range(1, steps + 1):
            distance, _ = tree.query(points[marching] + k * step * direction, distance_upper_bound=step, workers=-1)
            hit = np.isfinite(distance)
            met[marching[hit]] += 1
            marching = marching[~hit]
        alive = alive[(met[alive] + len(DIRECTIONS) - d - 1) / len(DIRECTIONS) >= share]
    out = np.zeros(len(points), bool)
    out[alive] = met[alive] / len(DIRECTIONS) >= share
    return out
