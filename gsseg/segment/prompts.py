"""Prompts that pick one object: a 3D point, a click in a view, or an explicit ID."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np
import torch
from scipy import ndimage
from scipy.spatial import cKDTree

from dataset_tools.cameras import CameraPose, PinholeCamera
from dataset_tools.infra.errors import InputError
from dataset_tools.scene import View
from gsseg.model.gaussians import Gaussians
from gsseg.render import Backend, get_backend, render
from gsseg.render.contributions import RegionWeights
from gsseg.render.pixel_labels import segment_pixels
from gsseg.render.projection import project_gaussians
from gsseg.segment.clicks import Click, ClickEvidence


def object_at_point(means: np.ndarray, labels: np.ndarray, point: np.ndarray, k: int = 20) -> int:
    """The mode of the labels of the ``k`` Gaussians nearest to ``point``.

    Args:
        means: (N, 3) Gaussian centres. labels: (N,) their labels. point: (3,) the prompt.

    Raises:
        InputError: the point lies outside the Gaussians' bounding box (padded by 5% of its diagonal).
    """
    point = np.asarray(point, np.float64)
    lo, hi = means.min(0), means.max(0)
    pad = 0.05 * np.linalg.norm(hi - lo)
    if np.any(point < lo - pad) or np.any(point > hi + pad):
        raise InputError(
            f"point {point.tolist()} lies outside the scene bounds {np.round(lo, 3).tolist()} .. "
            f"{np.round(hi, 3).tolist()}; pick a point on an object."
        )
    _, nearest = cKDTree(means).query(point, k=min(k, len(means)))
    values, counts = np.unique(labels[np.atleast_1d(nearest)], return_counts=True)
    return int(values[counts.argmax()])


def pick_object(means: np.ndarray, labels: np.ndarray, point: np.ndarray, k: int = 20) -> int:
    """The object ``object_at_point`` finds, refusing a point on the background (label 0)."""
    object_id = object_at_point(means, labels, point, k)
    if object_id == 0:
        raise InputError(
            f"the point {np.round(point, 3).tolist()} lies on the background (label 0); pick a point on an object."
        )
    return object_id


# The spread of the centre weighting of framed_object, in half the view's width and height.
FRAME_SPREAD = 0.5
# framed_object passes over an object holding less than this share of the views' blended
# weight (their mean): a speck no photo shows.
LEAST_SHOWN = 0.01


def framed_object(
    means: np.ndarray,
    selections: Mapping[int, np.ndarray],
    regions: RegionWeights,
    views: Sequence[CameraPose],
    spread: float = FRAME_SPREAD,
    least_shown: float = LEAST_SHOWN,
) -> int | None:
    """The object the photos frame: of ``selections`` (object ID -> (N,) bool Gaussians) that
    hold at least ``least_shown`` of the views' blended weight, the one that holds the most of
    it near the views' centres; None where none is shown so much. Each Gaussian's weight in a
    view (:meth:`RegionWeights.view_weights`) counts exp(-r^2 / (2 spread^2)) times, r the
    distance of its projected centre from the view's centre in half the view's width and
    height; each view gives its weight as a share of all it shows, so every view counts alike.

    Args:
        means: (N, 3) Gaussian centres. regions: their weights in ``views`` (V), in that order.
    """
    ids = list(selections)
    if not ids:
        return None
    members = np.stack([selections[k] for k in ids], 1).astype(np.float64)  # (N, M)
    weights = regions.view_weights()
    centred, shown, counted = np.zeros(len(ids)), np.zeros(len(ids)), 0
    for v in range(min(weights.shape[0], len(views))):
        row = weights.getrow(v)
        if not row.nnz:
            continue
        seen, total = row.indices, row.data.sum()
        cam, pose = views[v].camera, views[v].cam_from_world
        x = means[seen] @ pose[:3, :3].T + pose[:3, 3]
        z = np.maximum(x[:, 2], 1e-9)
        du = (cam.fx * x[:, 0] / z + cam.cx) / (cam.width / 2) - 1
        dv = (cam.fy * x[:, 1] / z + cam.cy) / (cam.height / 2) - 1
        centred += row.data * np.exp(-(du**2 + dv**2) / (2 * spread**2)) * (x[:, 2] > 0) @ members[seen] / total
        shown += row.data @ members[seen] / total
        counted += 1
    centred[shown < least_shown * max(counted, 1)] = -np.inf
    return ids[int(centred.argmax())] if np.isfinite(centred.max()) else None


def _border_distance(region: np.ndarray) -> np.ndarray:
    """(H, W) each pixel's distance to the nearest pixel outside ``region`` (H, W) bool (the
    image's border counts as outside)."""
    return ndimage.distance_transform_edt(np.pad(region, 1))[1:-1, 1:-1]


def _deepest(distance: np.ndarray) -> tuple[float, float]:
    """(u, v) of the pixel centre where ``distance`` (H, W) is largest."""
    row, col = np.unravel_index(distance.argmax(), distance.shape)
    return float(col) + 0.5, float(row) + 0.5


def deepest_pixel(region: np.ndarray) -> tuple[float, float]:
    """(u, v) of the pixel of ``region`` (H, W) bool farthest from its border (pixel centres)."""
    return _deepest(_border_distance(region))


@torch.no_grad()
def object_click(
    gaussians: Gaussians, selected: np.ndarray, views: Sequence[View], *, backend: str | Backend = "cpu"
) -> Click | None:
    """The click a user would make on the ``selected`` (N,) Gaussians: the pixel deepest
    inside the region where they hold the most blended weight (:func:`deepest_pixel`), in
    whichever of ``views`` that region lies deepest; None where no view shows them."""
    backend = get_backend(backend)
    best, depth_best = None, 0.0
    for view in views:
        pose = torch.as_tensor(view.cam_from_world, dtype=torch.float32, device=backend.device)
        region = segment_pixels(gaussians, selected.astype(np.uint8), view.camera, pose, backend=backend) == 1
        distance = _border_distance(region)
        depth = float(distance.max())
        if depth > depth_best:
            best, depth_best = Click(view.name, *_deepest(distance)), depth
    return best


def point_from_click(
    gaussians: Gaussians,
    camera: PinholeCamera,
    cam_from_world: np.ndarray,
    u: float,
    v: float,
    *,
    backend: str | Backend = "cpu",
) -> np.ndarray:
    """The 3D point seen at pixel (u, v) of a view: its rendered depth (alpha-normalised) lifted
    through the camera. (3,) float64 world coordinates."""
    if not (0 <= u < camera.width and 0 <= v < camera.height):
        raise InputError(f"click ({u}, {v}) is outside the {camera.width}x{camera.height} view; click inside it.")
    backend = get_backend(backend)
    out = render(
        gaussians.to(backend.device),
        camera,
        torch.as_tensor(cam_from_world, dtype=torch.float32, device=backend.device),
        with_features=False,
        backend=backend,
    )
    row, col = int(v), int(u)
    alpha = float(out.alpha[row, col])
    if alpha < 0.5:
        raise InputError(f"nothing opaque is rendered at ({u}, {v}) (alpha {alpha:.2f}); click on an object.")
    z = float(out.depth[row, col]) / alpha
    cam_point = np.array([(u - camera.cx) / camera.fx * z, (v - camera.cy) / camera.fy * z, z])
    R, t = np.asarray(cam_from_world)[:3, :3], np.asarray(cam_from_world)[:3, 3]
    return R.T @ (cam_point - t)


def click_evidence(
    gaussians: Gaussians,
    camera: PinholeCamera,
    cam_from_world: np.ndarray,
    u: float,
    v: float,
    positive: bool = True,
    *,
    radius: int = 1,
    band: int = 4,
    backend: str | Backend = "cpu",
) -> ClickEvidence:
    """What a click at pixel (u, v) of a view saw: each Gaussian's blended weight alpha_i T_i
    summed over the pixels within ``radius`` of it (a (2 radius + 1)^2 window), how much
    of it the view shows (its weight over the whole view over what its footprint would give
    unoccluded, o_i 2 pi sqrt(det Sigma2D_i); 0: hidden or off screen, 1: in full view), the
    share of its weight over the view that falls in the window, its weight over the
    view's frame (the pixels within ``band`` of the border, the window left out), the standard
    deviation of its footprint along the longest axis, and how far the click lies inside what
    a selection draws in the view (:attr:`ClickEvidence.inside`, a render of the selection).

    Raises:
        InputError: the click lies outside the view, or less than half opaque is rendered there.
    """
    if not (0 <= u < camera.width and 0 <= v < camera.height):
        raise InputError(f"click ({u}, {v}) is outside the {camera.width}x{camera.height} view; click inside it.")
    backend = get_backend(backend)
    g = gaussians.detach().to(backend.device)
    rows = np.full((camera.height, camera.width), 2, np.int64)  # 0: inside, 1: the window, 2: the frame
    rows[band : camera.height - band, band : camera.width - band] = 0
    row, col = int(v), int(u)
    window = rows[max(0, row - radius) : row + radius + 1, max(0, col - radius) : col + radius + 1]
    window[:] = 1
    pose = torch.as_tensor(cam_from_world, dtype=torch.float32, device=backend.device)
    weights = (
        backend.contributions(g.means, g.quats, g.scales, g.opacities, pose, camera, rows, 3).double().cpu().numpy()
    )
    alpha = weights[1].sum() / window.size
    if alpha < 0.5:
        raise InputError(f"nothing opaque is rendered at ({u}, {v}) (alpha {alpha:.2f}); click on an object.")
    with torch.no_grad():
        proj = project_gaussians(g.means, g.quats, g.scales, pose, camera, g.opacities)
        a, b, c = proj.conics.double().cpu().unbind(-1)
        det = a * c - b**2  # the conic is the inverse of the 2D covariance
        on_screen = (proj.radii > 0).cpu()
        footprint = torch.where(on_screen, g.opacities.double().cpu() * 2 * math.pi / torch.sqrt(det), torch.inf)
        half_trace = (a + c) / (2 * det)  # the covariance's largest eigenvalue, its longest axis's variance
        longest = half_trace + torch.sqrt(torch.clamp(half_trace**2 - 1 / det, min=0))
        spread = torch.where(on_screen, torch.sqrt(longest), 0.0).numpy()
    in_view = weights.sum(0)
    local = weights[1] / np.maximum(in_view, 1e-12)

    def inside(selected: np.ndarray) -> float:
        won = segment_pixels(g, selected.astype(np.uint8), camera, pose, backend=backend) == 1
        return float(ndimage.distance_transform_edt(won)[row, col])

    shown = np.clip(in_view / footprint.numpy(), 0, 1)
    return ClickEvidence(weights[1], positive, shown, local, weights[2], spread, inside)


def point_evidence(gaussians: Gaussians, point: np.ndarray, k: int = 20) -> ClickEvidence:
    """A 3D point as a positive click: the ``k`` Gaussians nearest to it, each weighted by its
    opacity."""
    means = gaussians.means.detach().cpu().numpy()
    _, nearest = cKDTree(means).query(np.asarray(point, np.float64), k=min(k, len(means)))
    weights = np.zeros(len(means))
    nearest = np.atleast_1d(nearest)
    weights[nearest] = gaussians.opacities.detach().cpu().numpy()[nearest] + 1e-6
    return ClickEvidence(weights, True)
