"""The plane a scene stands on (a table, the ground), from its SfM points.

The mask proposer takes regions that touch the image border for background. Where an object
fills the frame (a model on a table seen from close by) that rule takes the object too; the
height of each pixel's surface above the support tells them apart: the table lies on it, the
model rises from it. What rises far from the scene's points (a backdrop, the wall of a room
behind the table) is no part of it: beyond the plane's reach a surface has no height.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dataset_tools.scene import View


@dataclass(frozen=True)
class SupportPlane:
    """A world plane ``normal @ x + offset == 0`` (``normal`` (3,) a unit vector pointing to the
    cameras' side); heights are measured in units of ``scale``, the median distance of the
    scene's points from their median ``centre`` (3,). A surface farther than ``reach`` scales
    from the centre along the plane lies beyond the scene."""

    normal: np.ndarray
    offset: float
    scale: float
    centre: np.ndarray
    reach: float = 3.0

    def heights(self, view: View, depth: np.ndarray) -> np.ndarray:
        """(H, W) float32 height above the plane of the surface each pixel of ``view`` sees
        (``depth`` (H, W), 0 where nothing is opaque), in units of :attr:`scale`: NaN where
        nothing is seen, -inf where the surface lies beyond the scene's reach (nothing of the
        scene rises there)."""
        cam = view.camera
        H, W = depth.shape
        u, v = np.meshgrid(np.arange(W) + 0.5, np.arange(H) + 0.5)
        x_cam = np.stack([(u - cam.cx) / cam.fx * depth, (v - cam.cy) / cam.fy * depth, depth], -1)
        R, t = view.cam_from_world[:3, :3], view.cam_from_world[:3, 3]
        x_world = (x_cam - t) @ R  # R^T (x - t), row-wise
        height = (x_world @ self.normal + self.offset) / self.scale
        from_centre = x_world - self.centre
        along = from_centre - np.multiply.outer(from_centre @ self.normal, self.normal)  # its part in the plane
        height = np.where(np.linalg.norm(along, axis=-1) > self.reach * self.scale, -np.inf, height)
        return np.where(depth > 0, height, np.nan).astype(np.float32)


def support_plane(
    points: np.ndarray,
    centres: np.ndarray,
    *,
    tolerance: float = 0.02,
    max_below: float = 0.03,
    trials: int = 3000,
    seed: int = 0,
) -> SupportPlane | None:
    """The plane that most points lie on among those with every camera on one side and
    almost every point on the cameras' side (RANSAC over planes through three points).

    Args:
        points: (P, 3) SfM points. centres: (C, 3) camera centres.
        tolerance: a point lies on a plane within this share of the scene's scale.
        max_below: the largest share of the points on the far side of the plane.
        trials: planes tried; ``seed`` fixes the samples.
    Returns:
        The plane, or None when there are too few points or no plane qualifies.
    """
    if len(points) < 50 or not len(centres):
        return None
    centre = np.median(points, 0)
    scale = float(np.median(np.linalg.norm(points - centre, axis=1)))
    if scale <= 0:
        return None
    rng = np.random.default_rng(seed)
    best, best_count = None, 0
    for a, b, c in points[rng.integers(0, len(points), (trials, 3))]:
        normal = np.cross(b - a, c - a)
        norm = np.linalg.norm(normal)
        if norm == 0:
            continue
        normal, offset = normal / norm, -float(normal @ a) / norm
        side = centres @ normal + offset
        if not ((side > 0).all() or (side < 0).all()):
            continue  # cameras on both sides: a wall or a roof cutting through the capture
        if side[0] < 0:
            normal, offset = -normal, -offset
        height = points @ normal + offset
        if (height < -tolerance * scale).mean() > max_below:
            continue  # a support has (almost) nothing under it
        count = int((np.abs(height) < tolerance * scale).sum())
        if count > best_count:
            best, best_count = (normal, offset), count
    return None if best is None else SupportPlane(best[0], best[1], scale, centre)
