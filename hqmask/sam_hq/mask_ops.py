"""The numpy/OpenCV operations of SAM's automatic mask generator.

Boxes are XYXY in pixels, with SAM's convention for a box around a mask: the first and last
covered column and row (so a one-pixel mask has a box of zero width).
"""

from __future__ import annotations

import math

import cv2
import numpy as np


def point_grid(n_per_side: int) -> np.ndarray:
    """A regular grid of (n_per_side^2, 2) points (x, y) in [0, 1], cell centres, row-major."""
    offset = 1.0 / (2 * n_per_side)
    side = np.linspace(offset, 1 - offset, n_per_side)
    xs, ys = np.meshgrid(side, side)
    return np.stack([xs.ravel(), ys.ravel()], axis=1)


def crop_boxes(height: int, width: int, n_layers: int, overlap_ratio: float) -> tuple[np.ndarray, np.ndarray]:
    """SAM's crop pyramid: layer 0 is the whole image, layer i a 2^i x 2^i grid of crops that
    overlap by ``overlap_ratio`` of the short side (scaled per layer), column by column.

    Returns boxes (C, 4) int XYXY and their layer indices (C,).
    """
    boxes, layers = [[0, 0, width, height]], [0]
    short = min(height, width)
    for layer in range(1, n_layers + 1):
        n = 2**layer
        overlap = int(overlap_ratio * short * (2 / n))
        crop_w = math.ceil((overlap * (n - 1) + width) / n)
        crop_h = math.ceil((overlap * (n - 1) + height) / n)
        for x0 in (int((crop_w - overlap) * i) for i in range(n)):
            for y0 in (int((crop_h - overlap) * i) for i in range(n)):
                boxes.append([x0, y0, min(x0 + crop_w, width), min(y0 + crop_h, height)])
                layers.append(layer)
    return np.array(boxes, np.int64), np.array(layers, np.int64)


def stability_score(logits: np.ndarray, threshold: float, offset: float) -> np.ndarray:
    """IoU between the masks thresholded at ``threshold + offset`` and ``threshold - offset``.

    logits (B, H, W) -> (B,). A mask empty at both levels scores 0.
    """
    inner = np.count_nonzero(logits > threshold + offset, axis=(1, 2))
    outer = np.count_nonzero(logits > threshold - offset, axis=(1, 2))
    return inner / np.maximum(outer, 1)


def masks_to_boxes(masks: np.ndarray) -> np.ndarray:
    """Boxes (B, 4) XYXY of boolean masks (B, H, W); an empty mask gets [0, 0, 0, 0]."""
    rows, cols = masks.any(axis=2), masks.any(axis=1)
    H, W = masks.shape[1:]
    boxes = np.stack(
        [cols.argmax(1), rows.argmax(1), W - 1 - cols[:, ::-1].argmax(1), H - 1 - rows[:, ::-1].argmax(1)], axis=1
    )
    boxes[~rows.any(1)] = 0
    return boxes.astype(np.float32)


def box_iou(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Pairwise IoU of boxes a (N, 4) and b (M, 4), XYXY -> (N, M)."""
    area_a = (a[:, 2] - a[:, 0]) * (a[:, 3] - a[:, 1])
    area_b = (b[:, 2] - b[:, 0]) * (b[:, 3] - b[:, 1])
    lt = np.maximum(a[:, None, :2], b[None, :, :2])
    rb = np.minimum(a[:, None, 2:], b[None, :, 2:])
    inter = np.clip(rb - lt, 0, None).prod(axis=2)
    union = area_a[:, None] + area_b[None] - inter
    return np.divide(inter, union, out=np.zeros_like(inter, dtype=np.float64), where=union > 0)


def box_nms(boxes: np.ndarray, scores: np.ndarray, iou_threshold: float) -> np.ndarray:
    """Greedy non-maximum suppression: indices of the kept boxes, by decreasing score.

    A box is dropped when its IoU with a kept, higher-scoring box exceeds ``iou_threshold``;
    equal scores keep the earlier box.
    """
    order = np.argsort(-np.asarray(scores), kind="stable")
    iou = box_iou(boxes[order], boxes[order])
    suppressed = np.zeros(len(order), bool)
    keep = []
    for i in range(len(order)):
        if not suppressed[i]:
            keep.append(order[i])
            suppressed |= iou[i] > iou_threshold
    return np.array(keep, np.int64)


def near_crop_edge(boxes: np.ndarray, crop_box: np.ndarray, image_box: np.ndarray, atol: float = 20.0) -> np.ndarray:
    """Which boxes (B, 4), in image coordinates, touch an edge of ``crop_box`` that is not also
    an edge of the image (within ``atol`` pixels): such masks are cut off by the crop. -> (B,)"""
    near_crop = np.abs(boxes - crop_box[None]) <= atol
    near_image = np.abs(boxes - image_box[None]) <= atol
    return (near_crop & ~near_image).any(axis=1)


def remove_small_regions(mask: np.ndarray, min_area: int, mode: str) -> tuple[np.ndarray, bool]:
    """Fill holes (``mode="holes"``) or drop islands (``"islands"``) of ``mask`` (H, W) bool
    smaller than ``min_area`` pixels (8-connectivity). If every island is small, the largest
    stays. Returns the mask and whether it changed."""
    holes = mode == "holes"
    working = (mask != holes).astype(np.uint8)  # the background for holes, the mask for islands
    n, regions, stats, _ = cv2.connectedComponentsWithStats(working, connectivity=8)
    sizes = stats[1:, cv2.CC_STAT_AREA]
    small = np.flatnonzero(sizes < min_area) + 1
    if len(small) == 0:
        return mask, False
    if holes:
        return mask | np.isin(regions, small), True
    keep = np.setdiff1d(np.arange(1, n), small)
    if len(keep) == 0:
        keep = np.array([np.argmax(sizes) + 1])
    return np.isin(regions, keep), True
