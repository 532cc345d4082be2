"""A rough depth for every pixel of a view, from what the mask stage knows of the scene's
geometry: the SfM points the view observes, or (without them) where the associated objects
stand. It is only a starting point for optical flow between views far apart
(:func:`hqmask.optical_flow.geometric_flow`), which corrects it.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

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
    uv, z = uv[front], z[front]
    H, W = ids.shape
    px = np.clip(uv.astype(int), 0, [W - 1, H - 1])
    point_ids = ids[px[:, 1], px[:, 0]]
    rows, cols = np.indices((H, W))
    depth = np.empty((H, W), np.float32)
    for label in np.unique(ids):
        region = ids == label
        own = point_ids == label
        chosen = own if own.any() else np.ones(len(z), bool)
        _, nearest = cKDTree(uv[chosen]).query(np.stack([cols[region] + 0.5, rows[region] + 0.5], 1))
        depth[region] = z[chosen][nearest]
    return depth


def depth_from_anchors(view: CameraPose, ids: np.ndarray, anchors: dict[int, Anchor]) -> np.ndarray | None:
    """Each object's pixels take the depth of its anchor; the background, the depth of the
    farthest anchor (what lies behind the objects is at least as far).

    Args:
        view: the camera and pose. ids: (H, W) uint8 ID map. anchors: ID -> anchor.
    Returns:
        (H, W) float32 depths, or None when no anchor lies in front of the camera.
    """
    depths = {label: float(a.point @ view.cam_from_world[2, :3] + view.cam_from_world[2, 3])
              for label, a in anchors.items()}
    depths = {label: d for label, d in depths.items() if d > 0}
    if not depths:
        return None
    lut = np.full(256, max(depths.values()), np.float32)
    for label, d in depths.items():
        lut[label] = d
    return lut[ids]
