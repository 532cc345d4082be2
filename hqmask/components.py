"""Connected components of equal-ID regions of a label map (all IDs at once), in numba."""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, inline="always")
def _find(parent: np.ndarray, x: int) -> int:
    while parent[x] != x:
        parent[x] = parent[parent[x]]
        x = parent[x]
    return x


@numba.njit(cache=True)
def _label(ids: np.ndarray) -> tuple[np.ndarray, int]:
    H, W = ids.shape
    parent = np.empty(H * W, np.int32)
    comp = np.empty((H, W), np.int32)
    n = 0
    for i in range(H):
        for j in range(W):
            v = ids[i, j]
            cur = -1
            for di, dj in ((0, -1), (-1, -1), (-1, 0), (-1, 1)):
                ni, nj = i + di, j + dj
                if ni < 0 or nj < 0 or nj >= W or ids[ni, nj] != v:
                    continue
                r = _find(parent, comp[ni, nj])
                if cur == -1:
                    cur = r
                elif r != cur:
                    lo, hi = min(r, cur), max(r, cur)
                    parent[hi] = lo
                    cur = lo
            if cur == -1:
                parent[n] = n
                cur = n
                n += 1
            comp[i, j] = cur
    compact = np.full(n, -1, np.int32)
    count = 0
    for k in range(n):
        r = _find(parent, k)
        if compact[r] == -1:
            compact[r] = count
            count += 1
        compact[k] = compact[r]
    for i in range(H):
        for j in range(W):
            comp[i, j] = compact[comp[i, j]]
    return comp, count


def label_components(ids: np.ndarray) -> tuple[np.ndarray, int]:
    """Label 8-connected regions of equal ID, background (0) included.

    Args:
        ids: (H, W) uint8 label map.
    Returns:
        (components (H, W) int32 numbered 0..n-1 in raster order of their first pixel, n).
    """
    return _label(np.ascontiguousarray(ids, dtype=np.uint8))
