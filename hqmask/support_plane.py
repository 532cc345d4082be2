"""The plane a scene stands on (a table, the ground, the rock under a statue), from its SfM
points.

The mask proposer takes regions that touch the image border for background. Where an object
fills the frame (a model on a table seen from close by) that rule takes the object too; the
height of each pixel's surface above the support tells them apart: the table lies on it, the
model rises from it. What rises far from the scene (a backdrop, the wall of a room behind the
table, the trees behind an orbit's cameras) is no part of it: beyond the plane's reach a
surface has no height.

Where the cameras orbit a point (:func:`orbit_of`: they surround the point their optical axes
pass nearest to), the support is the surface under that point: of the upright planes the
cameras look down on, the one that holds most points around the point's foot, whatever lies
under it (a granite bear's rock above the forest floor, a bronze head's cushion on a table);
its reach ends at the cameras' ring. Elsewhere (a forward-facing capture, a dome above a
table) it is the plane that most points lie on with almost nothing under it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dataset_tools.scene import View


@dataclass(frozen=True)
class Heights:
    """One view's ``values`` (H, W) float32, the height above the support plane of the surface
    each pixel sees (NaN where nothing is seen, -inf beyond the plane's reach), and whether
    what rises from the plane is cut from it where it leaves it (``contact``: a plane found
    under an orbit's focus, the surface the orbited object stands on); ``observed`` (H, W)
    bool, the pixels where the view observes an SfM point (None: not known)."""

    values: np.ndarray
    contact: bool
    observed: np.ndarray | None = None


@dataclass(frozen=True)
class SupportPlane:
    """A world plane ``normal @ x + offset == 0`` (``normal`` (3,) a unit vector pointing to the
    cameras' side); heights are measured in units of ``scale``, the median distance of the
    scene's points from their median. A surface farther than ``reach`` scales from ``centre``
    (3,) along the plane lies beyond the scene. ``under_focus``: found under an orbit's focus
    (:func:`support_plane`)."""

    normal: np.ndarray
    offset: float
    scale: float
    centre: np.ndarray
    reach: float = 3.0
    under_focus: bool = False

    def heights(self, view: View, depth: np.ndarray) -> Heights:
        """The height above the plane of the surface each pixel of ``view`` sees (``depth``
        (H, W), 0 where nothing is opaque), in units of :attr:`scale`: NaN where nothing is
        seen, -inf where the surface lies beyond the scene's reach (nothing of the scene rises
        there); to be cut at the contact where the plane lies under an orbit's focus; and the
        pixels where ``view`` observes its SfM points (``view.uv``)."""
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
        observed = np.zeros((H, W), bool)
        uv = np.floor(view.uv).astype(np.int64).reshape(-1, 2)
        inside = (uv >= 0).all(1) & (uv[:, 0] < W) & (uv[:, 1] < H)
        observed[uv[inside, 1], uv[inside, 0]] = True
        return Heights(np.where(depth > 0, height, np.nan).astype(np.float32), self.under_focus, observed)


@dataclass(frozen=True)
class Orbit:
    """Cameras around a ``focus`` (3,): the ``up`` (3,) their images share (the mean of their
    upward image axes) and ``ring``, the distance along the ground from the focus within which
    no camera stands (the 5th percentile of theirs)."""

    focus: np.ndarray
    up: np.ndarray
    ring: float


def orbit_of(cam_from_world: np.ndarray, least_arc: float = 180.0, least_spread: float = 0.05) -> Orbit | None:
    """The orbit of the cameras ``cam_from_world`` (C, 3, 4), or None where they do not orbit:
    the point nearest all their optical axes (least squares) is the focus when the axes cross
    (the smallest eigenvalue of the normal matrix is at least ``least_spread`` of the largest:
    parallel axes, as in a forward-facing capture, have no focus) and the cameras, seen from
    above the focus, surround it over at least ``least_arc`` degrees."""
    R, centres = cam_from_world[:, :, :3], _centres(cam_from_world)
    axes, ups = R[:, 2], -R[:, 1]
    across = np.eye(3) - axes[:, :, None] * axes[:, None, :]  # (C, 3, 3) projections off each axis
    normal_matrix = across.sum(0)
    eigen = np.linalg.eigvalsh(normal_matrix)
    if len(centres) < 3 or eigen[0] < least_spread * eigen[-1]:
        return None
    focus = np.linalg.solve(normal_matrix, np.einsum("cij,cj->i", across, centres))
    up = ups.mean(0)
    up /= max(float(np.linalg.norm(up)), 1e-12)
    flat = centres - focus
    flat -= np.outer(flat @ up, up)
    e1 = np.linalg.svd(np.eye(3) - np.outer(up, up))[0][:, 0]
    e2 = np.cross(up, e1)
    angles = np.sort(np.degrees(np.arctan2(flat @ e2, flat @ e1)))
    gap = float(np.max(np.diff(np.concatenate([angles, [angles[0] + 360.0]]))))
    if 360.0 - gap < least_arc:
        return None
    return Orbit(focus, up, float(np.percentile(np.linalg.norm(flat, axis=1), 5)))


def support_plane(
    points: np.ndarray,
    cam_from_world: np.ndarray,
    *,
    tolerance: float = 0.02,
    max_below: float = 0.03,
    max_tilt: float = 45.0,
    around: float = 0.3,
    trials: int = 3000,
    seed: int = 0,
) -> SupportPlane | None:
    """The plane the scene stands on (RANSAC over planes through three points, each with every
    camera on one side, the best refitted to the points on it by least squares). In an orbit
    (:func:`orbit_of`): of the planes within ``max_tilt`` degrees of the cameras' up with the
    focus above them, the one that holds the most points within ``around`` times the cameras'
    ring from the focus's foot; its reach the ring where that is nearer than
    :attr:`SupportPlane.reach`, measured from the focus. Elsewhere: of the planes with at
    most ``max_below`` of the points on the far side, the one that holds the most points; its
    reach :attr:`SupportPlane.reach` from the points' median.

    Args:
        points: (P, 3) SfM points. cam_from_world: (C, 3, 4) the cameras.
        tolerance: a point lies on a plane within this share of the scene's scale.
        trials: planes tried; ``seed`` fixes the samples.
    Returns:
        The plane, or None when there are too few points or no plane qualifies.
    """
    if len(points) < 50 or not len(cam_from_world):
        return None
    centres = _centres(cam_from_world)
    centre = np.median(points, 0)
    scale = float(np.median(np.linalg.norm(points - centre, axis=1)))
    if scale <= 0:
        return None
    orbit = orbit_of(cam_from_world)
    rng = np.random.default_rng(seed)
    best, best_count, best_on = None, 0, None
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
        on = np.abs(height) < tolerance * scale
        if orbit is None:
            if (height < -tolerance * scale).mean() > max_below:
                continue  # a support has (almost) nothing under it
        else:
            above = float(orbit.focus @ normal + offset)
            if normal @ orbit.up < np.cos(np.radians(max_tilt)) or above <= 0:
                continue  # a wall, or a plane over the focus
            from_foot = points - (orbit.focus - above * normal)
            along = from_foot - np.outer(from_foot @ normal, normal)
            on &= np.linalg.norm(along, axis=1) < around * orbit.ring
        count = int(on.sum())
        if count > best_count:
            best, best_count, best_on = (normal, offset), count, on
    if best is None:
        return None
    best = _refit(points[best_on], *best)
    if orbit is None:
        return SupportPlane(best[0], best[1], scale, centre)
    reach = min(SupportPlane.reach, orbit.ring / scale)
    return SupportPlane(best[0], best[1], scale, orbit.focus, reach, under_focus=True)


def _centres(cam_from_world: np.ndarray) -> np.ndarray:
    """(C, 3) the centres -R^T t of the cameras ``cam_from_world`` (C, 3, 4)."""
    return -np.einsum("cji,cj->ci", cam_from_world[:, :, :3], cam_from_world[:, :, 3])


def _refit(inliers: np.ndarray, normal: np.ndarray, offset: float) -> tuple[np.ndarray, float]:
    """The least-squares plane through ``inliers`` (K, 3) (the normal of their smallest spread),
    facing as ``normal`` (3,) does; ``normal`` and ``offset`` as they are with under 3."""
    if len(inliers) < 3:
        return normal, offset
    mean = inliers.mean(0)
    fitted = np.linalg.svd(inliers - mean, full_matrices=False)[2][-1]
    fitted = fitted if fitted @ normal >= 0 else -fitted
    return fitted, -float(fitted @ mean)
