"""Dense optical flow between two views (OpenCV DIS) and what is carried along it."""

from __future__ import annotations

import cv2
import numpy as np


def flow_between(image: np.ndarray, other: np.ndarray) -> np.ndarray:
    """Where each pixel of ``image`` is seen in ``other``.

    Args:
        image, other: (H, W, 3) uint8 RGB of one size.
    Returns:
        (H, W, 2) float32 flow: pixel (x, y) of ``image`` lies at (x, y) + flow in ``other``.
    """
    dis = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM)
    return dis.calc(cv2.cvtColor(image, cv2.COLOR_RGB2GRAY), cv2.cvtColor(other, cv2.COLOR_RGB2GRAY), None)


def _sample(values: np.ndarray, flow: np.ndarray, interpolation: int, fill: float) -> np.ndarray:
    H, W = flow.shape[:2]
    gx, gy = np.meshgrid(np.arange(W, dtype=np.float32), np.arange(H, dtype=np.float32))
    return cv2.remap(values, gx + flow[..., 0], gy + flow[..., 1], interpolation, borderMode=cv2.BORDER_CONSTANT,
                     borderValue=fill)


def pull_labels(labels: np.ndarray, flow: np.ndarray, fill: int = 0) -> np.ndarray:
    """Carry the other view's label map into this one along ``flow`` (from :func:`flow_between`
    of this view and the other): (H, W) uint8 -> (H, W) uint8, nearest label, ``fill`` where
    the flow leaves the other image."""
    return _sample(labels, flow, cv2.INTER_NEAREST, fill)


def consistent_flow(forward: np.ndarray, backward: np.ndarray, tolerance: float) -> np.ndarray:
    """(H, W) bool: pixels whose flow to the other view and back returns within ``tolerance``
    pixels (not occluded, not mismatched, inside the other image). forward: this -> other,
    backward: other -> this, both (H, W, 2)."""
    back = _sample(backward, forward, cv2.INTER_LINEAR, np.inf)
    return np.linalg.norm(forward + back, axis=-1) < tolerance


def matching_colors(image: np.ndarray, other: np.ndarray, flow: np.ndarray, tolerance: float) -> np.ndarray:
    """(H, W) bool: pixels of ``image`` whose colour in ``other``, found along ``flow`` (this ->
    other), differs by less than ``tolerance`` (0..255) in every channel."""
    seen = _sample(other, flow, cv2.INTER_LINEAR, 0).astype(np.int16)
    return np.abs(seen - image.astype(np.int16)).max(axis=-1) < tolerance
