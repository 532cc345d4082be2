"""Operations on object-ID maps shared by every stage: overlap counts and ID matching."""

from __future__ import annotations

import numpy as np
from scipy.optimize import linear_sum_assignment


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
