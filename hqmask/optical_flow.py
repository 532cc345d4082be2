"""Dense optical flow between two views (OpenCV DIS) and what is carried along it.

Views of one capture may differ in size (undistorted views with a camera each differ by a
few pixels): the other view is brought to this view's size first (:func:`to_size`), and the
flow takes up the small change of scale."""

from __future__ import annotations

import cv2
import numpy as np

from dataset_tools.cameras import CameraPose

FLOW_MAX_SIDE = 512  # flow is computed at most this large (longest side, pixels)


def to_size(array: np.ndarray, shape: tuple[int, ...], *, nearest: bool) -> np.ndarray:
    """``array`` (H', W', ...) resized to the (H, W) of ``shape``: nearest for label maps, area
    averaging for images; returned as is when the sizes agree."""
    if array.shape[:2] == tuple(shape[:2]):
        return array
    return cv2.resize(array, (shape[1], shape[0]), interpolation=cv2.INTER_NEAREST if nearest else cv2.INTER_AREA)


def _working_size(shape: tuple[int, ...], max_side: int) -> tuple[int, int]:
    """(w, h): the size flow is computed at, the longest side at most ``max_side``."""
    H, W = shape[:2]
    scale = min(1.0, max_side / max(H, W))
    return max(1, round(W * scale)), max(1, round(H * scale))


def _dis(image: np.ndarray, other: np.ndarray) -> np.ndarray:
    """DIS flow between two (h, w, 3) uint8 RGB images of one size: (h, w, 2) float32."""
    grey = [cv2.cvtColor(x, cv2.COLOR_RGB2GRAY) for x in (image, other)]
    return cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM).calc(grey[0], grey[1], None)


def _upscale(flow: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    """A flow computed at a smaller size, resampled and rescaled to (H, W) of ``shape``."""
    H, W = shape[:2]
    h, w = flow.shape[:2]
    if (h, w) == (H, W):
        return flow
    return cv2.resize(flow, (W, H), interpolation=cv2.INTER_LINEAR) * np.array([W / w, H / h], np.float32)


def flow_between(image: np.ndarray, other: np.ndarray, *, max_side: int = FLOW_MAX_SIDE) -> np.ndarray:
    """Where each pixel of ``image`` is seen in ``other`` brought to ``image``'s size.

    The flow is computed on copies whose longest side is at most ``max_side`` (DIS's cost
    grows with the pixels; what association needs is where regions go, not sub-pixel
    boundaries) and scaled back up.

    Args:
        image: (H, W, 3) uint8 RGB. other: (H', W', 3) uint8 RGB, resized to (H, W) when it differs.
    Returns:
        (H, W, 2) float32 flow: pixel (x, y) of ``image`` lies at (x, y) + flow in the resized ``other``.
    """
    w, h = _working_size(image.shape, max_side)
    flow = _dis(to_size(image, (h, w), nearest=False), to_size(other, (h, w), nearest=False))
    return _upscale(flow, image.shape)


def depth_flow(view: CameraPose, other: CameraPose, depth: np.ndarray) -> np.ndarray:
    """The flow from ``view`` to ``other`` that a depth map implies: each pixel lifted to 3D at
    its ``depth`` (H, W) and projected into ``other`` (brought to ``view``'s size).
    Returns (H, W, 2) float32."""
    H, W = depth.shape
    rows, cols = np.indices((H, W), dtype=np.float64)
    cam = view.camera
    in_view = np.stack([(cols + 0.5 - cam.cx) / cam.fx * depth, (rows + 0.5 - cam.cy) / cam.fy * depth, depth], -1)
    world = (in_view - view.cam_from_world[:, 3]) @ view.cam_from_world[:, :3]  # R.T (x - t)
    seen = world @ other.cam_from_world[:, :3].T + other.cam_from_world[:, 3]
    z = np.maximum(seen[..., 2], 1e-9)
    # the other camera at this view's size
    target = other.camera.resized(W, H)
    u = target.fx * seen[..., 0] / z + target.cx - 0.5
    v = target.fy * seen[..., 1] / z + target.cy - 0.5
    return np.stack([u - cols, v - rows], -1).astype(np.float32)


def plane_homography(view: CameraPose, other: CameraPose, depth: float, shape: tuple[int, ...]) -> np.ndarray:
    """(3, 3) map from a pixel of ``view`` to where a fronto-parallel plane at ``depth`` in
    front of ``view`` puts it in ``other`` brought to ``view``'s (H, W) ``shape``, both in
    OpenCV's integer-centred pixel coordinates: K' (d R + t e3^T) K^-1."""
    H, W = shape[:2]
    half = np.array([[1.0, 0.0, -0.5], [0.0, 1.0, -0.5], [0.0, 0.0, 1.0]])  # COLMAP -> OpenCV pixels
    K_view = half @ view.camera.K
    K_other = half @ other.camera.resized(W, H).K
    R = other.cam_from_world[:, :3] @ view.cam_from_world[:, :3].T
    t = other.cam_from_world[:, 3] - R @ view.cam_from_world[:, 3]
    return K_other @ (depth * R + np.outer(t, [0.0, 0.0, 1.0])) @ np.linalg.inv(K_view)


def pull_along_plane(
    labels: np.ndarray, view: CameraPose, other: CameraPose, depth: float, shape: tuple[int, ...]
) -> np.ndarray:
    """The other view's (H', W') label map carried into ``view`` (size ``shape``) as if it lay
    on a fronto-parallel plane at ``depth`` in front of ``view`` (nearest, 0 outside)."""
    H, W = shape[:2]
    warp = plane_homography(view, other, depth, shape)
    return cv2.warpPerspective(
        to_size(labels, (H, W), nearest=True),
        warp,
        (W, H),
        flags=cv2.INTER_NEAREST | cv2.WARP_INVERSE_MAP,
        borderMode=cv2.BORDER_CONSTANT,
        borderValue=0,
    )


def geometric_flow(
    image: np.ndarray,
    other: np.ndarray,
    view: CameraPose,
    other_view: CameraPose,
    depth: np.ndarray | None,
    *,
    max_side: int = FLOW_MAX_SIDE,
) -> np.ndarray:
    """:func:`flow_between` for views far apart: ``other`` is first warped along the flow a
    rough ``depth`` (H, W) of ``image`` implies (:func:`depth_flow`), DIS finds what is left,
    and the two are composed, all at the working size. Without a depth it is plain
    :func:`flow_between`. Returns (H, W, 2) float32 flow into ``other`` brought to ``image``'s size."""
    if depth is None:
        return flow_between(image, other, max_side=max_side)
    w, h = _working_size(image.shape, max_side)
    small = CameraPose(view.camera.resized(w, h), view.cam_from_world)
    prior = depth_flow(small, other_view, to_size(depth, (h, w), nearest=True))
    warped = _sample(to_size(other, (h, w), nearest=False), prior, cv2.INTER_LINEAR, 0)
    residual = _dis(to_size(image, (h, w), nearest=False), warped)
    return _upscale(residual + _sample(prior, residual, cv2.INTER_LINEAR, 0), image.shape)


def _sample(values: np.ndarray, flow: np.ndarray, interpolation: int, fill: float) -> np.ndarray:
    H, W = flow.shape[:2]
    gx, gy = np.meshgrid(np.arange(W, dtype=np.float32), np.arange(H, dtype=np.float32))
    return cv2.remap(
        values, gx + flow[..., 0], gy + flow[..., 1], interpolation, borderMode=cv2.BORDER_CONSTANT, borderValue=fill
    )


def pull_labels(labels: np.ndarray, flow: np.ndarray, fill: int = 0) -> np.ndarray:
    """Carry the other view's label map into this one along ``flow`` (from :func:`flow_between`
    of this view and the other): (H', W') uint8 -> (H, W) uint8, nearest label, ``fill`` where
    the flow leaves the other image."""
    return _sample(to_size(labels, flow.shape, nearest=True), flow, cv2.INTER_NEAREST, fill)


def consistent_flow(forward: np.ndarray, backward: np.ndarray, tolerance: float) -> np.ndarray:
    """(H, W) bool: pixels whose flow to the other view and back returns within ``tolerance``
    pixels (not occluded, not mismatched, inside the other image). forward: this -> other,
    backward: other -> this, both (H, W, 2)."""
    back = _sample(backward, forward, cv2.INTER_LINEAR, np.inf)
    return np.linalg.norm(forward + back, axis=-1) < tolerance


def matching_colors(image: np.ndarray, other: np.ndarray, flow: np.ndarray, tolerance: float) -> np.ndarray:
    """(H, W) bool: pixels of ``image`` whose colour in ``other``, found along ``flow`` (this ->
    other), differs by less than ``tolerance`` (0..255) in every channel."""
    seen = _sample(to_size(other, flow.shape, nearest=False), flow, cv2.INTER_LINEAR, 0).astype(np.int16)
    return np.abs(seen - image.astype(np.int16)).max(axis=-1) < tolerance
