"""A rough depth for every pixel of a view, from what the mask stage knows of the scene's
geometry: the SfM points the view observes, or (without them) where the associated objects
stand. It is only a starting point for optical flow between views far apart
(:func:`hqmask.optical_flow.geometric_flow`), which corrects it.
"""

from __future__ import annotations

import cv2
import numpy as np

from dataset_tools.cameras import CameraPose
from hqmask.association.anchors import Anchor


def depth_from_points(view: CameraPose, uv: np.ndarray, xyz: np.ndarray, ids: np.ndarray) -> np.ndarray | None:
    """Each pixel takes the camera depth of the nearest observed SfM point carrying the same
    ID (of any ID where its own has no point).

    Args:
        view: the camera and pose. uv: (M, 2) pixel coordinates of the observations in the
            view. xyz: (M, 3) their points. ids: (H, W) uint8 ID map of the view.
    Returns:
        (H, W) float32 depths, or None when the view observes no point in front of it.
    """
    z = xyz @ view.cam_from_world[2, :3] + view.cam_from_world[2, 3]
    front = z > 0
    if not front.any():
        return None
    H, W = ids.shape
    px = np.clip(uv[front].astype(int), 0, [W - 1, H - 1])
    z = z[front]
    point_ids = ids[px[:, 1], px[:, 0]]
    depth = np.empty((H, W), np.float32)
    for label in np.unique(ids):
        own = point_ids == label
        region = ids == label
        depth[region] = _nearest_point_depth(px[own] if own.any() else px, z[own] if own.any() else z, (H, W))[region]
    return depth


def _nearest_point_depth(px: np.ndarray, z: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """(H, W): the depth ``z`` of the point nearest to every pixel (points at integer pixels
    ``px`` (M, 2) as (col, row); OpenCV's labelled distance transform, a 5x5 mask)."""
    seeds = np.full(shape, 255, np.uint8)
    seeds[px[:, 1], px[:, 0]] = 0
    _, labels = cv2.distanceTransformWithLabels(seeds, cv2.DIST_L2, 5, labelType=cv2.DIST_LABEL_PIXEL)
    at_seed = np.zeros(labels.max() + 1, np.float32)
    at_seed[labels[px[:, 1], px[:, 0]]] = z
    return at_seed[labels]


def depth_from_anchors(view: CameraPose, ids: np.ndarray, anchors: dict[int, Anchor]) -> np.ndarray | None:
    """Each object's pixels take the depth of its anchor; so do the pixels of the disk its
    anchor and size project to, where the view's own IDs show nothing (an object this view's
    masks missed is still where the other views put it), nearer objects in front; the rest,
    the depth of the farthest anchor (what lies behind the objects is at least as far).

    Args:
        view: the camera and pose. ids: (H, W) uint8 ID map. anchors: ID -> anchor.
    Returns:
        (H, W) float32 depths, or None when no anchor lies in front of the camera.
    """
    R, t = view.cam_from_world[:, :3], view.cam_from_world[:, 3]
    seen = {label: R @ a.point + t for label, a in anchors.items()}
    seen = {label: x for label, x in seen.items() if x[2] > 0}
    if not seen:
        return None
    depth = np.full(ids.shape, max(x[2] for x in seen.values()), np.float32)
    cam = view.camera
    for label, x in sorted(seen.items(), key=lambda kv: -kv[1][2]):  # far to near
        radius = anchors[label].radius * 0.5 * (cam.fx + cam.fy) / x[2]
        center = (int(cam.fx * x[0] / x[2] + cam.cx), int(cam.fy * x[1] / x[2] + cam.cy))
        disk = np.zeros(ids.shape, np.uint8)
        cv2.circle(disk, center, max(1, int(radius)), 1, -1)
        depth[(disk > 0) & (ids == 0)] = x[2]
    for label, x in seen.items():
        depth[ids == label] = x[2]
    return depth
