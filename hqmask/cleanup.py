"""Noise removal on multi-label object-ID maps: closing without bleeding, then small
components reassigned to the dominant label around them.

1. **Closing** (3x3 square by default) fills background gaps inside and between the parts
   of one object, never pixels of another object. It is the per-label closing computed on a
   dilation in which each pixel carries at most one label: a background pixel is dilated
   into only when its neighbourhood holds exactly one object ID. Object pixels never change.
2. **Small components**: every 8-connected region of one ID (background included, so holes
   are treated alike) smaller than ``min_area`` pixels takes the ID that covers most of its
   boundary ring (the pixels outside it touching it; ties go to the smaller ID). A speck
   surrounded by background becomes background; a hole inside an object is filled with it.
   Repeated until no small component changes; components of ``min_area`` or more pixels are
   never touched.
"""

from __future__ import annotations

import cv2
import numpy as np

from hqmask.components import component_stats, label_components, ring_votes

def close_labels(ids: np.ndarray, size: int = 3) -> np.ndarray:
    """Per-label morphological closing that only fills background. (H, W) uint8 -> (H, W) uint8."""
    if size <= 1:
        return ids
    kernel = np.ones((size, size), np.uint8)
    as16 = ids.astype(np.uint16)
    hi = cv2.dilate(as16, kernel)  # largest ID around
    lo = cv2.erode(np.where(as16 == 0, 256, as16).astype(np.uint16), kernel)  # smallest object ID around
    dilated = np.where((as16 == 0) & (hi == lo), hi, as16)  # 0 where the neighbours disagree
    # erosion of each label of ``dilated``: a pixel keeps label l if its whole neighbourhood is l
    keep = (cv2.dilate(dilated, kernel) == dilated) & (cv2.erode(dilated, kernel) == dilated)
    fill = (ids == 0) & keep & (dilated > 0)
    return np.where(fill, dilated, ids).astype(np.uint8)


def remove_small_components(ids: np.ndarray, min_area: int = 500, max_rounds: int = 8) -> np.ndarray:
    """Reassign every equal-ID component under ``min_area`` pixels to its dominant ring label.

    (H, W) uint8 -> (H, W) uint8.
    """
    out = ids.copy()
    for _ in range(max_rounds):
        comp, n = label_components(out)
        area, current = component_stats(comp, out, n)
        small = area < min_area
        if not small.any():
            break
        winner = ring_votes(comp, out, small)
        change = (winner >= 0) & (winner != current)
        if not change.any():
            break
        lut = np.where(change, winner, current).astype(np.uint8)
        out = lut[comp]
    return out


def clean_mask(ids: np.ndarray, min_area: int = 500, close_size: int = 3) -> np.ndarray:
    """The full noise removal: closing, then small-component reassignment.

    Args:
        ids: (H, W) uint8 object-ID map, 0 = background.
        min_area: components with fewer pixels are reassigned.
        close_size: side of the square closing element (1 disables closing).
    Returns:
        (H, W) uint8 cleaned map.
    """
    return remove_small_components(close_labels(ids, close_size), min_area)
