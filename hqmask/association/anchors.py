"""Where an object stands, from its segments and the camera poses alone (no SfM points): the
point nearest to the rays through the centroids of its segments (an anchor), and its size.

A segment's centroid is not the projection of one fixed 3D point, but for the views of one
object it stays within a fraction of the object's size of the projection of its centre, so
anchors of two tracks of one object fall close together and each projects inside the other's
segments; anchors of two objects do not. That survives steps between views far larger than
optical flow can follow.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dataset_tools.cameras import PinholeCamera

MIN_RAY_ANGLE = np.deg2rad(2.0)  # rays closer to parallel than this do not fix a point


@dataclass(frozen=True)
class Sighting:
    """An object seen in one view: the ray through its segment's centroid and the segment's size.

    origin (3,), direction (3,) unit world vectors; area in pixels; focal in pixels."""

    view: int
    origin: np.ndarray
    direction: np.ndarray
    area: float
    focal: float


@dataclass(frozen=True)
class Anchor:
    """point (3,) in world coordinates; radius, the object's size in world units; spread, the
    widest angle between its rays in radians (how well the point's depth is fixed)."""

    point: np.ndarray
    radius: float
    spread: float


def sighting(view: int, mask: np.ndarray, camera: PinholeCamera, cam_from_world: np.ndarray) -> Sighting:
    """The sighting of the object covering the (H, W) bool ``mask`` of a view."""
    ys, xs = np.nonzero(mask)
    u, v = xs.mean() + 0.5, ys.mean() + 0.5
    R, t = cam_from_world[:, :3], cam_from_world[:, 3]
    d = R.T @ np.array([(u - camera.cx) / camera.fx, (v - camera.cy) / camera.fy, 1.0])
    return Sighting(view, -R.T @ t, d / np.linalg.norm(d), float(len(xs)), 0.5 * (camera.fx + camera.fy))


def _nearest_point(sightings: list[Sighting], weights: np.ndarray) -> np.ndarray:
    """The point minimising the weighted squared distances to the sightings' rays."""
    A = np.zeros((3, 3))
    b = np.zeros(3)
    for w, s in zip(weights, sightings):
        P = np.eye(3) - np.outer(s.direction, s.direction)
        A += w * P
        b += w * P @ s.origin
    return np.linalg.solve(A, b)


def triangulate(sightings: list[Sighting], rounds: int = 3) -> Anchor | None:
    """The anchor of an object seen in ``sightings``: the point nearest to their rays (squared
    distances weighted by the square root of each segment's area, then ``rounds`` times
    reweighted by a Cauchy function of each ray's distance in object radii, so that a
    segment that merged the object with a neighbour, or kept only a piece of it, does not
    drag the point), and the median size its segments give at that depth. None when fewer
    than two rays, rays closer to parallel than ``MIN_RAY_ANGLE``, or a point behind a camera."""
    if len(sightings) < 2:
        return None
    dirs = np.stack([s.direction for s in sightings])
    spread = float(np.arccos(np.clip(dirs @ dirs.T, -1, 1)).max())
    if spread < MIN_RAY_ANGLE:
        return None
    prior = np.sqrt([s.area for s in sightings])
    weights = prior
    for _ in range(rounds + 1):
        point = _nearest_point(sightings, weights)
        depths = np.array([(point - s.origin) @ s.direction for s in sightings])
        if (depths <= 0).any():
            return None
        sizes = np.array([np.sqrt(s.area / np.pi) * d / s.focal for s, d in zip(sightings, depths)])
        radius = float(np.median(sizes))
        off = np.array(
            [np.linalg.norm((point - s.origin) - ((point - s.origin) @ s.direction) * s.direction) for s in sightings]
        )
        weights = prior / (1.0 + (off / max(radius, 1e-12)) ** 2)
    return Anchor(point, radius, spread)


def rays_meet(a: Sighting, b: Sighting, tolerance: float) -> bool:
    """Whether the rays of two sightings pass within ``tolerance`` object radii of each other
    in front of both cameras (the epipolar constraint, with the object's size as the margin;
    the radius is ``b``'s segment size at the depth where the rays come closest)."""
    cross = np.cross(a.direction, b.direction)
    gap = b.origin - a.origin
    norm = np.linalg.norm(cross)
    if norm < np.sin(MIN_RAY_ANGLE):  # near parallel: nothing to check
        return True
    ta = np.dot(np.cross(gap, b.direction), cross) / norm**2
    tb = np.dot(np.cross(gap, a.direction), cross) / norm**2
    if ta <= 0 or tb <= 0:
        return False
    distance = abs(np.dot(gap, cross)) / norm
    return distance <= tolerance * np.sqrt(b.area / np.pi) * tb / b.focal


def project(point: np.ndarray, camera: PinholeCamera, cam_from_world: np.ndarray) -> tuple[int, int] | None:
    """The pixel (row, col) ``point`` falls on, or None when it lies behind the camera or
    outside the image."""
    x = cam_from_world[:, :3] @ point + cam_from_world[:, 3]
    if x[2] <= 0:
        return None
    col, row = int(np.floor(camera.fx * x[0] / x[2] + camera.cx)), int(np.floor(camera.fy * x[1] / x[2] + camera.cy))
    if not (0 <= row < camera.height and 0 <= col < camera.width):
        return None
    return row, col
