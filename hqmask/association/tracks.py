"""Geometric association for photo collections: segments linked through shared SfM points.

1. Every SfM observation falls in one segment of its view (or in background).
2. Two segments of different views are linked when they agree on the points both views
   observe: most points of each that the other view also sees lie in the other
   (mutual containment >= ``link_ratio``, at least ``min_shared`` points). Links are taken
   strongest first (most shared points) into a union-find that refuses to join two groups
   holding different segments of one view: the core objects. A segment covering two
   objects can join one of them but never chains the two together.
3. Pieces joined: a core object seen in fewer views than those in which its points lie
   inside one other object is a piece of that object (the halves of a mask cut alike in
   two views link to each other) and takes its ID.
4. Merges repaired: a segment whose points belong to two or more objects (each with a fair
   share of them) is split between them by nearest point.
5. Conflicts and leftovers: a segment outside every core object of two or more segments
   (a split half, a merged blob, a speck) joins the object, or background, that holds most
   of its points in the other views; a segment with no points stays background.
"""

from __future__ import annotations

from collections import defaultdict

import numpy as np
from scipy.spatial import cKDTree

from dataset_tools.scene import View
from hqmask.association.common import ViewExclusiveUnion, compact_ids


def _segment_of_points(view: View, seg: np.ndarray, n_points: int) -> np.ndarray:
    """(P,) local segment under each SfM point in this view; -1 where the view does not see it."""
    out = np.full(n_points, -1, np.int64)
    px = np.clip(view.uv.astype(int), 0, [seg.shape[1] - 1, seg.shape[0] - 1])
    out[view.point_ids] = seg[px[:, 1], px[:, 0]]
    return out


def _split_by_points(view: View, region: np.ndarray, pts: np.ndarray, objs: np.ndarray,
                     ratio: float, min_points: int) -> list[tuple[int, np.ndarray]]:
    """[(object, pixel mask)] partitioning ``region`` by the object of the nearest SfM point
    when two or more objects each hold ``ratio`` of its points (and ``min_points``); else []."""
    known = objs != -1
    if ratio <= 0 or known.sum() < 2 * min_points:
        return []
    values, counts = np.unique(objs[known], return_counts=True)
    strong = values[(counts >= ratio * known.sum()) & (counts >= min_points)]
    if len(strong) < 2:
        return []
    keep = np.isin(objs, strong)
    row_of = dict(zip(view.point_ids.tolist(), range(len(view.point_ids))))
    rows = [row_of[int(p)] for p in pts[keep]]
    _, nearest = cKDTree(view.uv[rows]).query(np.argwhere(region)[:, ::-1] + 0.5)
    owner = objs[keep][nearest]
    parts = []
    for obj in strong:
        pixels = np.zeros_like(region)
        pixels[region] = owner == obj
        parts.append((int(obj), pixels))
    return parts


def _pieces(obj_at: np.ndarray, objects: np.ndarray) -> dict[int, int]:
    """{piece: whole} for the core objects that are pieces of another: in more views than
    the piece appears in itself, most of its points that the view sees lie inside the whole.
    A real object's points fall in its own segments wherever it is seen, so it is never
    anyone's piece; the halves of a mask cut alike in two views are.

    Args:
        obj_at: (V, P) core object under each SfM point in each view; -1 where the view
            does not see the point or it falls in no core object, -2 in background.
        objects: the core objects' IDs.
    """
    whole_of = {}
    for obj in objects.tolist():
        inside = obj_at == obj
        seen_in = inside.any(1)
        pts = inside.any(0)
        tally: dict[int, int] = defaultdict(int)
        for v in np.flatnonzero(~seen_in):
            there = obj_at[v, pts]
            values, counts = np.unique(there[there != -1], return_counts=True)
            if len(values) and values[np.argmax(counts)] >= 0:
                tally[int(values[np.argmax(counts)])] += 1
        if tally:
            whole, n_views = max(tally.items(), key=lambda kv: (kv[1], -kv[0]))
            if n_views > seen_in.sum():
                whole_of[obj] = whole
    return whole_of


def associate_tracks(
    views: list[View],
    segments: list[np.ndarray],
    n_points: int,
    *,
    link_ratio: float = 0.6,
    min_shared: int = 3,
    split_ratio: float = 0.3,
) -> list[np.ndarray]:
    """Associate segments across views through the SfM points they share.

    Args:
        views: the views (their ``point_ids`` and ``uv`` observations are used).
        segments: per view, (H, W) int32 segment map (0 = background).
        n_points: number of SfM points (rows of ``Scene.points``).
        split_ratio: a segment whose points belong to two or more objects, each holding at
            least this share of them (and ``min_shared`` points), is split between them:
            every pixel goes to the object of its nearest point (a merged mask repaired).
            0 disables splitting.
    Returns:
        per view, (H, W) uint8 consistent ID map.
    """
    V = len(views)
    seg_at = np.stack([_segment_of_points(v, s, n_points) for v, s in zip(views, segments)])  # (V, P)
    offsets = np.concatenate([[0], np.cumsum([int(s.max()) + 1 for s in segments])])
    node = np.where(seg_at >= 0, seg_at + offsets[:V, None], -1)  # global node id, background nodes included
    is_bg = np.zeros(offsets[-1], bool)
    is_bg[offsets[:V]] = True
    view_of_node = np.repeat(np.arange(V), np.diff(offsets))
    links = []
    for a in range(V):
        for b in range(a + 1, V):
            both = (seg_at[a] >= 0) & (seg_at[b] >= 0)
            if not both.any():
                continue
            na, nb = node[a, both], node[b, both]
            pairs, shared = np.unique(np.stack([na, nb]), axis=1, return_counts=True)
            size_a = dict(zip(*np.unique(na, return_counts=True)))
            size_b = dict(zip(*np.unique(nb, return_counts=True)))
            for (x, y), s in zip(pairs.T, shared):
                if is_bg[x] or is_bg[y] or s < min_shared:
                    continue
                if s >= link_ratio * size_a[x] and s >= link_ratio * size_b[y]:
                    links.append((int(s), int(x), int(y)))
    uf = ViewExclusiveUnion([{int(v)} for v in view_of_node])
    for _, x, y in sorted(links, key=lambda l: (-l[0], l[1], l[2])):
        uf.union(x, y)
    root = uf.roots()
    members = defaultdict(int)
    for r in root[~is_bg]:
        members[int(r)] += 1
    core = np.array([not is_bg[i] and members[int(root[i])] >= 2 for i in range(len(root))])
    obj_of_node = np.where(core, root, -1)
    obj_of_node[is_bg] = -2  # background
    whole_of = _pieces(np.where(node >= 0, obj_of_node[np.maximum(node, 0)], -1), np.unique(root[core]))
    for piece in whole_of:
        whole = whole_of[piece]
        while whole in whole_of:  # a piece of a piece (no cycles: a whole is seen in more views)
            whole = whole_of[whole]
        root[root == piece] = whole
    obj_of_node[core] = root[core]
    # each point's object: majority over views of the core object it falls in (or background)
    votes: dict[int, dict[int, int]] = defaultdict(lambda: defaultdict(int))
    for v in range(V):
        seen = np.flatnonzero(node[v] >= 0)
        for p, o in zip(seen, obj_of_node[node[v, seen]]):
            if o != -1:
                votes[int(p)][int(o)] += 1
    point_obj = {p: max(c.items(), key=lambda kv: (kv[1], -kv[0]))[0] for p, c in votes.items()}
    global_of = []
    for v, seg in enumerate(segments):
        seg = segments[v] = seg.copy()
        g = np.full(int(seg.max()) + 1, -1, np.int64)
        for local in range(1, len(g)):
            n = offsets[v] + local
            pts = np.flatnonzero(seg_at[v] == local)
            objs = np.array([point_obj.get(int(p), -1) for p in pts], np.int64)
            parts = _split_by_points(views[v], seg == local, pts, objs, split_ratio, min_shared)
            if parts:
                for k, (obj, pixels) in enumerate(parts):
                    if k:  # every further part becomes a new local segment
                        seg[pixels] = len(g)
                        g = np.append(g, -1)
                    g[local if k == 0 else len(g) - 1] = obj if obj >= 0 else -1
                continue
            if core[n]:
                g[local] = root[n]
                continue
            known = objs[objs != -1]
            if len(known):
                values, counts = np.unique(known, return_counts=True)
                best = values[np.lexsort((-values, counts))[-1]]  # most points, ties to the smaller
                g[local] = best if best >= 0 else -1
        global_of.append(g)
    return compact_ids(global_of, segments)
