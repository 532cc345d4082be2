"""Helpers shared by the association methods."""

from __future__ import annotations

import numpy as np

from dataset_tools.infra.errors import OptionError


class UnionFind:
    """Disjoint sets over 0..n-1 (path halving, union by smaller root)."""

    def __init__(self, n: int) -> None:
        self.parent = np.arange(n)

    def find(self, x: int) -> int:
        p = self.parent
        while p[x] != x:
            p[x] = p[p[x]]
            x = p[x]
        return int(x)

    def union(self, a: int, b: int) -> None:
        ra, rb = self.find(a), self.find(b)
        if ra != rb:
            self.parent[max(ra, rb)] = min(ra, rb)

    def roots(self) -> np.ndarray:
        return np.array([self.find(i) for i in range(len(self.parent))], dtype=np.int64)


class ViewExclusiveUnion(UnionFind):
    """Union-find whose sets never hold two members seen in the same view.

    ``views[i]`` is the set of views member ``i`` appears in; ``union`` refuses (returns
    False) when the two sets share more than ``tolerate`` views (none by default), which is
    how a segment covering two objects is kept from chaining them together.
    """

    def __init__(self, views: list[set[int]]) -> None:
        super().__init__(len(views))
        self.views = [set(v) for v in views]

    def union(self, a: int, b: int, tolerate: int = 0) -> bool:  # type: ignore[override]
        ra, rb = self.find(a), self.find(b)
        if ra == rb:
            return True
        if len(self.views[ra] & self.views[rb]) > tolerate:
            return False
        lo, hi = min(ra, rb), max(ra, rb)
        self.parent[hi] = lo
        self.views[lo] |= self.views[hi]
        return True


def compact_ids(global_of: list[np.ndarray], segments: list[np.ndarray]) -> list[np.ndarray]:
    """Paint per-view segment maps with global track numbers, renumbered 1..K by total area.

    Args:
        global_of: per view, (n_v + 1,) int64 global track of each local segment (index 0 and
            unassigned segments: -1, painted as background).
        segments: per view, (H, W) int32 segment maps.
    Returns:
        per view, (H, W) uint8 ID maps.
    """
    area: dict[int, int] = {}
    for g, seg in zip(global_of, segments):
        counts = np.bincount(seg.ravel(), minlength=len(g))
        for local, track in enumerate(g):
            if track >= 0 and local > 0:
                area[int(track)] = area.get(int(track), 0) + int(counts[local])
    order = sorted((t for t in area if area[t] > 0), key=lambda t: (-area[t], t))
    if len(order) > 255:
        raise OptionError(
            f"association found {len(order)} objects, more than the 255 an 8-bit mask can hold; "
            "raise {min_area} or use a proposer that makes fewer, larger segments."
        )
    final = {t: k + 1 for k, t in enumerate(order)}
    out = []
    for g, seg in zip(global_of, segments):
        lut = np.array([final.get(int(t), 0) if i > 0 else 0 for i, t in enumerate(g)], dtype=np.uint8)
        out.append(lut[seg])
    return out
