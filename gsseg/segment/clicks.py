"""Selections made by several clicks, each for or against: positive clicks join the objects
they land on (the parts of one object that the masks split), a negative click inside the
selection splits it (an object the masks joined to another).

A click is lifted to a 3D point (:func:`gsseg.segment.prompts.point_from_click`). The
selection starts as every object a positive point picks. A negative point on a selected
object splits the selection: over a graph of the selected Gaussians that joins each to its
nearest neighbours, with edges as long as their distance in position plus their distance in
object feature (each over its median along the graph), every selected Gaussian follows the
click it is nearest to; those nearest a negative click leave. Two parts that touch in 3D stay
connected through their contact, two parts metres apart (a statue's head and the bush behind
it in every photo) are far apart along the graph even when the masks gave them one label.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree

from dataset_tools.infra.errors import InputError
from gsseg.segment.prompts import object_at_point

GRAPH_NEIGHBOURS = 10  # each selected Gaussian is joined to this many nearest others
SEED_GAUSSIANS = 5  # a click starts the graph search from this many Gaussians nearest its point


@dataclass(frozen=True)
class Click:
    """Pixel (u, v) of the view named ``view``, for (``positive``) or against the selection."""

    view: str
    u: float
    v: float
    positive: bool = True


def _check_points(points: np.ndarray, name: str) -> np.ndarray:
    points = np.asarray(points, np.float64).reshape(-1, 3)
    if not np.isfinite(points).all():
        raise InputError(f"{name}: give finite 3D points.")
    return points


def select_by_points(
    means: np.ndarray,
    features: np.ndarray,
    labels: np.ndarray,
    positives: np.ndarray,
    negatives: np.ndarray | None = None,
    k: int = 20,
) -> np.ndarray:
    """The Gaussians selected by positive and negative 3D points.

    Args:
        means: (N, 3) Gaussian centres.
        features: (N, F) their object features.
        labels: (N,) their labels (0: background).
        positives: (P, 3) points, P >= 1: each selects the object of :func:`object_at_point`.
        negatives: (Q, 3) points: each that lands on a selected object splits the selection.
        k: Gaussians around a point that vote on its object.

    Returns:
        (N,) bool selection.

    Raises:
        InputError: no positive point, or one on the background.
    """
    positives = _check_points(positives, "positive clicks")
    negatives = _check_points(np.zeros((0, 3)) if negatives is None else negatives, "negative clicks")
    if len(means) != len(labels) or len(features) != len(labels):
        raise ValueError(f"means {means.shape}, features {features.shape} and labels {labels.shape} must have N rows")
    if not len(positives):
        raise InputError("a selection needs at least one positive click; add one on the object.")
    picked = {object_at_point(means, labels, p, k) for p in positives}
    if 0 in picked:
        raise InputError("a positive click lies on the background (label 0); click on the object.")
    selected = np.isin(labels, sorted(picked))
    inside = [q for q in negatives if object_at_point(means, labels, q, k) in picked]
    if not inside:
        return selected
    index = np.flatnonzero(selected)
    nearest = split_by_graph(means[index], features[index], positives, np.asarray(inside))
    selected[index[~nearest]] = False
    return selected


def split_by_graph(means: np.ndarray, features: np.ndarray, positives: np.ndarray, negatives: np.ndarray) -> np.ndarray:
    """(M,) bool: which of M Gaussians lie nearer a positive point than a negative one along
    their nearest-neighbour graph (:data:`GRAPH_NEIGHBOURS`), edges weighted by position plus
    feature distance, each over its median. Gaussians no click reaches through the graph
    follow the nearest click in space."""
    m = len(means)
    k = min(GRAPH_NEIGHBOURS, m - 1)
    tree = cKDTree(means)
    if k < 1:
        return np.ones(m, bool)
    dist, nbr = tree.query(means, k=k + 1)
    rows, cols, dist = np.repeat(np.arange(m), k), nbr[:, 1:].ravel(), dist[:, 1:].ravel()
    fdist = np.linalg.norm(features[rows] - features[cols], axis=1)
    weight = dist / max(np.median(dist), 1e-12) + fdist / max(np.median(fdist), 1e-12) + 1e-9
    graph = coo_matrix((weight, (rows, cols)), shape=(m, m)).tocsr()
    seeds, positive = [], []
    for points, sign in ((positives, True), (negatives, False)):
        for p in points:
            _, near = tree.query(p, k=min(SEED_GAUSSIANS, m))
            seeds += np.atleast_1d(near).tolist()
            positive += [sign] * np.atleast_1d(near).size
    sign_of: dict[int, bool] = {}
    for seed, sign in zip(seeds, positive):  # a Gaussian near clicks of both kinds stays
        sign_of[seed] = sign_of.get(seed, False) or sign
    distance, _, source = dijkstra(
        graph, directed=False, indices=sorted(sign_of), min_only=True, return_predecessors=True
    )
    reached = np.isfinite(distance)
    keep = np.array([sign_of.get(int(s), True) for s in source], bool)
    if not reached.all():
        clicks = np.concatenate([positives, negatives])
        side = np.concatenate([np.ones(len(positives), bool), np.zeros(len(negatives), bool)])
        _, closest = cKDTree(clicks).query(means[~reached])
        keep[~reached] = side[closest]
    return keep
