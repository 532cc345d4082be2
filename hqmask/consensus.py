"""Multi-view consensus: each view's ID map corrected by the maps of its nearest views.

After association an ID names the same object in every view, so the maps of nearby views,
carried into a view along dense optical flow, are independent witnesses of its labels. A
pixel takes the label with the most weight among its own and its witnesses'. The view's own
object label counts ``own_weight`` (1.5: two agreeing neighbours overrule it, one does not);
its own background counts ``own_background_weight`` (0.9: one neighbour that sees an object
there fills it in, since an object a proposer missed in one view is the commonest error
that no choice of IDs can repair). A witness counts only where the forward and backward
flows between the two views agree within ``fb_tolerance`` pixels and the colour the flow
points at matches within ``color_tolerance`` grey levels, so occluded pixels, and views too
far apart for the flow to follow, vote nothing (without the colour test, flow that is
consistent but wrong on weak texture spoiled exact masks on an orbit of views 30 degrees
apart). With a rough depth of every view (:mod:`hqmask.depth_prior`) the flow starts from
where that depth says each pixel goes (:func:`hqmask.optical_flow.geometric_flow`), which
lets it follow steps between views that plain optical flow cannot. DEVA's propagation does
the same along a video.
"""

from __future__ import annotations

import numpy as np
from tqdm import tqdm

from dataset_tools.cameras import CameraPose
from hqmask.optical_flow import consistent_flow, geometric_flow, matching_colors, pull_labels, to_size


def vote(labels: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Per pixel, the label with the largest total weight.

    Args:
        labels: (M, H, W) uint8 candidate labels, the view's own first.
        weights: (M, H, W) float32 weight of each candidate (0: no vote).
    Returns:
        (H, W) uint8; ties go to the earliest candidate, so to the view's own label.
    """
    score = np.stack([np.where(w > 0, ((labels == label) * weights).sum(0), -1.0) for label, w in zip(labels, weights)])
    return np.take_along_axis(labels, score.argmax(0)[None], 0)[0]


def nearest_views(views: list[CameraPose], k: int) -> list[list[int]]:
    """Each view's ``k`` nearest other views by camera centre; equal distances (an orbit's
    views on either side) are ordered by the centres' coordinates, never by file order."""
    centers = np.stack([v.center for v in views])
    dist = np.sum((centers[:, None] - centers[None]) ** 2, axis=-1)
    return [
        sorted((j for j in range(len(views)) if j != v), key=lambda j: (dist[v, j], tuple(centers[j])))[:k]
        for v in range(len(views))
    ]


def multiview_consensus(
    images: list[np.ndarray],
    ids: list[np.ndarray],
    views: list[CameraPose],
    *,
    depths: list[np.ndarray | None] | None = None,
    neighbours: int = 4,
    fb_tolerance: float = 2.0,
    color_tolerance: float = 10.0,
    own_weight: float = 1.5,
    own_background_weight: float = 0.9,
    progress: bool = False,
) -> list[np.ndarray]:
    """Correct view-consistent ID maps by their ``neighbours`` nearest views (camera centres).

    Args:
        images: per view, (H, W, 3) uint8 RGB (for the optical flow).
        ids: per view, (H, W) uint8 view-consistent ID map.
        views: per view, its camera and pose.
        depths: per view, an (H, W) rough depth to start the flow from, or None (plain flow).
    Returns:
        per view, (H, W) uint8 ID map. A neighbour of another image size (undistorted views of
        one capture differ by a few pixels) is resized to the view's size first; the flow
        takes up the small change of scale.
    """
    depths = depths or [None] * len(ids)
    near = nearest_views(views, neighbours)
    # Flows of a pair of mutual neighbours serve both views: (v, j) -> flows v -> j and j -> v,
    # computed while j was corrected and kept until v is.
    saved: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]] = {}
    out = []
    for v in tqdm(range(len(ids)), desc="multi-view consensus", unit="view", disable=not progress):
        labels = [ids[v]]
        weights = [np.where(ids[v] > 0, own_weight, own_background_weight).astype(np.float32)]
        H, W = ids[v].shape
        for j in near[v]:
            resized = ids[j].shape != (H, W)
            image, other = to_size(images[j], (H, W), nearest=False), to_size(ids[j], (H, W), nearest=True)
            if (v, j) in saved:
                to_j, from_j = saved.pop((v, j))
            else:
                # the neighbour brought to this view's size, with its camera
                view_j = CameraPose(views[j].camera.resized(W, H), views[j].cam_from_world) if resized else views[j]
                to_j = geometric_flow(images[v], images[j], views[v], views[j], depths[v])
                from_j = geometric_flow(
                    image,
                    images[v],
                    view_j,
                    views[v],
                    None if depths[j] is None else to_size(depths[j], (H, W), nearest=True),
                )
                if not resized and j > v and v in near[j]:
                    saved[j, v] = from_j, to_j
            labels.append(pull_labels(other, to_j))
            trusted = consistent_flow(to_j, from_j, fb_tolerance) & matching_colors(
                images[v], image, to_j, color_tolerance
            )
            weights.append(trusted.astype(np.float32))
        out.append(vote(np.stack(labels), np.stack(weights)))
    return out
