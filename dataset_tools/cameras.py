"""Camera intrinsics: the pinhole cameras renderers use, and distorted source cameras."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

PINHOLE_MODELS = ("PINHOLE", "SIMPLE_PINHOLE")
# 3D-GS's near plane, for cameras whose scene gives no better bound (see ``scene_near_plane``).
DEFAULT_NEAR = 0.2


def rotation_angle(R: np.ndarray) -> float:
    """The angle in degrees of the rotation (3, 3) ``R``."""
    return float(np.degrees(np.arccos(np.clip((np.trace(R) - 1) / 2, -1, 1))))


def turned_frames(cam_from_world: dict[str, np.ndarray], order: list[str], degrees: float = 45.0) -> list[str]:
    """The images of ``order`` turned by more than ``degrees`` from the image just before them,
    where both are posed (``cam_from_world``: name -> (3, 4) [R | t]). Along a video or any
    capture taken a few degrees apart, such a turn is a camera mapped to the far side of the
    object (a *flip*: the scene looks alike from two sides)."""
    pairs = [(a, b) for a, b in zip(order, order[1:]) if a in cam_from_world and b in cam_from_world]
    return [b for a, b in pairs if rotation_angle(cam_from_world[b][:, :3] @ cam_from_world[a][:, :3].T) > degrees]


@dataclass(frozen=True)
class PinholeCamera:
    """An undistorted pinhole camera. Pixel centres lie at half-integer coordinates
    (COLMAP's convention): pixel (row i, column j) is centred at (u, v) = (j + 0.5, i + 0.5).
    Renderers draw nothing nearer than ``near`` (camera-space depth, scene units)."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    near: float = DEFAULT_NEAR

    @property
    def K(self) -> np.ndarray:
        """Intrinsic matrix, (3, 3) float64."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def pixels(self, points: np.ndarray, min_z: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Where camera-space ``points`` (P, 3) fall in the image: the rows of those deeper than
        ``min_z`` that fall in it (K,), and the column and row of the pixel each falls in
        (K,) int."""
        with np.errstate(divide="ignore", invalid="ignore"):
            u = points[:, 0] / points[:, 2] * self.fx + self.cx
            v = points[:, 1] / points[:, 2] * self.fy + self.cy
        rows = np.flatnonzero((points[:, 2] > min_z) & (u >= 0) & (u < self.width) & (v >= 0) & (v < self.height))
        return rows, u[rows].astype(int), v[rows].astype(int)

    def resized(self, width: int, height: int) -> PinholeCamera:
        """The same camera for an image resampled to ``width`` x ``height``."""
        sx, sy = width / self.width, height / self.height
        return PinholeCamera(width, height, self.fx * sx, self.fy * sy, self.cx * sx, self.cy * sy, self.near)


@dataclass(frozen=True)
class SourceCamera:
    """A COLMAP camera with lens distortion, at the resolution of the image files.

    ``model`` and ``params`` follow COLMAP's camera models (e.g. SIMPLE_RADIAL: f, cx, cy, k).
    """

    model: str
    width: int
    height: int
    params: tuple[float, ...]


@dataclass(frozen=True)
class CameraPose:
    """A pinhole camera placed in the world: ``cam_from_world`` (3, 4) float64, COLMAP axes
    (x right, y down, z forward). Scene views have the same two attributes."""

    camera: PinholeCamera
    cam_from_world: np.ndarray

    @property
    def center(self) -> np.ndarray:
        """Camera centre in world coordinates, (3,)."""
        return -self.cam_from_world[:, :3].T @ self.cam_from_world[:, 3]
