"""Multi-view consensus: each view's ID map corrected by the maps of its nearest views.

After association an ID names the same object in every view, so the maps of nearby views,
carried into a view along dense optical flow, are independent witnesses of its labels. A
pixel takes the label with the most weight among its own and its witnesses', its own view
counting ``own_weight`` (1.5 by default: two agreeing neighbours overrule it, one does not).
A witness counts only where the forward and backward flows between the two views agree
within ``fb_tolerance`` pixels and the colour the flow points at matches within
``color_tolerance`` grey levels, so occluded pixels, and views too far apart for the flow to
follow, vote nothing (without the colour test, flow that is consistent but wrong on weak
texture spoiled exact masks on an orbit of views 30 degrees apart). This fills in objects
that a view's masks missed and evens out boundaries that wander from view to view, which no
choice of IDs can do; DEVA's propagation does the same along a video.
"""

from __future__ import annotations

import cv2
import numpy as np
from tqdm import tqdm

from hqmask.optical_flow import consistent_flow, flow_between, matching_colors, pull_labels


def vote(labels: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Per pixel, the label with the largest total weight.

    Args:
        labels: (M, H, W) uint8 candidate labels, the view's own first.
        weights: (M, H, W) float32 weight of each candidate (0: no vote).
    Returns:
        (H, W) uint8; ties go to the earliest candidate, so to the view's own label.
    """
    score = np.stack([np.where(w > 0, ((labels == l) * weights).sum(0), -1.0) for l, w in zip(labels, weights)])
    return np.take_along_axis(labels, score.argmax(0)[None], 0)[0]


def multiview_consensus(
    images: list[np.ndarray],
    ids: list[np.ndarray],
    centers: np.ndarray,
    *,
    neighbours: int = 4,
    fb_tolerance: float = 2.0,
    color_tolerance: float = 10.0,
    own_weight: float = 1.5,
    progress: bool = False,
) -> list[np.ndarray]:
    """Correct view-consistent ID maps by their ``neighbours`` nearest views (camera centres).

    Args:
        images: per view, (H, W, 3) uint8 RGB (for the optical flow).
        ids: per view, (H, W) uint8 view-consistent ID map.
        centers: (V, 3) camera centres.
    Returns:
        per view, (H, W) uint8 ID map. A neighbour of another image size (undistorted views of
        one capture differ by a few pixels) is resized to the view's size first; the flow
        takes up the small change of scale.
    """
    dist = np.sum((centers[:, None] - centers[None]) ** 2, axis=-1)
    near = [[j for j in np.argsort(dist[v], kind="stable") if j != v][:neighbours] for v in range(len(ids))]
    # Flows of a pair of mutual neighbours serve both views: (v, j) -> flows v -> j and j -> v,
    # computed while j was corrected and kept until v is.
    saved: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]] = {}
    out = []
    for v in tqdm(range(len(ids)), desc="multi-view consensus", unit="view", disable=not progress):
        labels, weights = [ids[v]], [np.full(ids[v].shape, own_weight, np.float32)]
        H, W = ids[v].shape
        for j in near[v]:
            image, other = images[j], ids[j]
            resized = other.shape != (H, W)
            if resized:
                image = cv2.resize(image, (W, H), interpolation=cv2.INTER_AREA)
                other = cv2.resize(other, (W, H), interpolation=cv2.INTER_NEAREST)
            if (v, j) in saved:
                to_j, from_j = saved.pop((v, j))
            else:
                to_j, from_j = flow_between(images[v], image), flow_between(image, images[v])
                if not resized and j > v and v in near[j]:
                    saved[j, v] = from_j, to_j
            labels.append(pull_labels(other, to_j))
            trusted = consistent_flow(to_j, from_j, fb_tolerance) & matching_colors(images[v], image, to_j,
                                                                                     color_tolerance)
            weights.append(trusted.astype(np.float32))
        out.append(vote(np.stack(labels), np.stack(weights)))
    return out
