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


@numba.njit(cache=True)
def ring_votes(comp: np.ndarray, ids: np.ndarray, small: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The ID covering most of the boundary ring of each small component, and whether it is
    the only one.

    Args:
        comp: (H, W) int32 component labels. ids: (H, W) uint8 IDs. small: (n,) bool, the
            components to vote for.

    Returns:
        winner (n,) int64: the winning ID (ties to the smaller ID), -1 for components that are
        not small or have no ring; alone (n,) bool: the winner covers the whole ring and the
        component does not touch the image border (it lies inside that one region). Each ring
        pixel (8-connected, outside the component) counts once.
    """
    H, W = ids.shape
    n = small.shape[0]
    offsets = np.zeros(n + 1, np.int64)
    for i in range(H):
        for j in range(W):
            if small[comp[i, j]]:
                offsets[comp[i, j] + 1] += 1
    for c in range(n):
        offsets[c + 1] += offsets[c]
    cursor = offsets[:-1].copy()
    pixels = np.empty(offsets[n], np.int64)
    for i in range(H):
        for j in range(W):
            c = comp[i, j]
            if small[c]:
                pixels[cursor[c]] = i * W + j
                cursor[c] += 1
    winner = np.full(n, -1, np.int64)
    alone = np.zeros(n, np.bool_)
    stamp = np.full(H * W, -1, np.int64)  # the last component that counted this ring pixel
    votes = np.zeros(256, np.int64)
    for c in range(n):
        if offsets[c] == offsets[c + 1]:
            continue
        votes[:] = 0
        border = False
        for k in range(offsets[c], offsets[c + 1]):
            i, j = pixels[k] // W, pixels[k] % W
            border = border or i == 0 or j == 0 or i == H - 1 or j == W - 1
            for di in range(-1, 2):
                for dj in range(-1, 2):
                    ni, nj = i + di, j + dj
                    if ni < 0 or nj < 0 or ni >= H or nj >= W:
                        continue
                    q = ni * W + nj
                    if comp[ni, nj] != c and stamp[q] != c:
                        stamp[q] = c
                        votes[ids[ni, nj]] += 1
        best, total = -1, 0
        for v in range(256):
            total += votes[v]
            if votes[v] > 0 and (best < 0 or votes[v] > votes[best]):
                best = v
        winner[c] = best
        alone[c] = best >= 0 and votes[best] == total and not border
    return winner, alone


@numba.njit(cache=True)
def component_stats(comp: np.ndarray, ids: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Area (n,) int64 and ID (n,) int64 of every component, in one pass."""
    area = np.zeros(n, np.int64)
    value = np.zeros(n, np.int64)
    H, W = ids.shape
    for i in range(H):
        for j in range(W):
            c = comp[i, j]
            area[c] += 1
            value[c] = ids[i, j]
    return area, value
