"""Operations on object-ID maps shared by every stage: overlap counts, ID matching and the box
around a mask."""

from __future__ import annotations

import numpy as np
from scipy.optimize import linear_sum_assignment


def mask_box(mask: np.ndarray, margin: int = 0, min_side: int = 0) -> tuple[slice, slice]:
    """(rows, columns) of the box around the (H, W) bool ``mask`` (not empty), widened by
    ``margin`` pixels and cut to the image, then grown about its centre to ``min_side`` a side
    (or the image's side), kept within the image."""

    def span(nonzero: np.ndarray, size: int) -> slice:
        lo, hi = max(int(nonzero[0]) - margin, 0), min(int(nonzero[-1]) + 1 + margin, size)
        grow = max(0, min(min_side, size) - (hi - lo))
        start = min(max(lo - grow // 2, 0), size - (hi - lo + grow))
        return slice(start, start + hi - lo + grow)

    return span(np.flatnonzero(mask.any(1)), mask.shape[0]), span(np.flatnonzero(mask.any(0)), mask.shape[1])


def overlap(pred: np.ndarray, gt: np.ndarray) -> np.ndarray:
    """Pixel counts of every (pred ID, gt ID) pair. (..., ) uint8 maps -> (256, 256) int64."""
    idx = pred.astype(np.int64).ravel() * 256 + gt.astype(np.int64).ravel()
    return np.bincount(idx, minlength=256 * 256).reshape(256, 256)


def match_ids(counts: np.ndarray) -> np.ndarray:
    """One-to-one matching of predicted to ground-truth IDs maximising the shared pixels.

    Args:
        counts: (256, 256) overlap counts, rows predicted IDs, columns ground-truth IDs.
    Returns:
        (256,) int64 map from predicted ID to ground-truth ID; 0 stays 0, unmatched IDs map
        to -1 (they agree with nothing).
    """
    mapping = np.full(256, -1, dtype=np.int64)
    mapping[0] = 0
    rows = np.flatnonzero(counts[1:].sum(1)) + 1
    cols = np.flatnonzero(counts[:, 1:].sum(0)) + 1
    if len(rows) and len(cols):
        r, c = linear_sum_assignment(-counts[np.ix_(rows, cols)])
        mapping[rows[r]] = cols[c]
    return mapping


def matched_error(pred: np.ndarray, gt: np.ndarray) -> float:
    """Fraction of pixels whose ID disagrees with ``gt`` after the best one-to-one renaming of
    ``pred``'s IDs (so a consistent permutation of IDs costs nothing)."""
    mapping = match_ids(overlap(pred, gt))
    return float(np.mean(mapping[pred] != gt))


def consistent_fraction(preds: list[np.ndarray], gts: list[np.ndarray]) -> float:
    """Share of ground-truth object pixels (ID > 0) that carry their matched ID, with one
    matching of predicted to ground-truth IDs for the whole scene (Hungarian on the pixel
    overlap summed over all views)."""
    counts = sum(overlap(p, g) for p, g in zip(preds, gts))
    mapping = match_ids(counts)
    hit = total = 0
    for p, g in zip(preds, gts):
        obj = g > 0
        hit += int(np.count_nonzero(mapping[p[obj]] == g[obj]))
        total += int(np.count_nonzero(obj))
    return hit / max(total, 1)
