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
4. Merges repaired: each point belongs to the object (or background) its views vote for,
   a background vote counting ``background_vote`` (a mask that misses part of an object is
   a commoner error than one that covers floor in most views); a segment whose points
   belong to two or more objects (each with a fair share of its object points), or to an
   object and background (a fair share of all its points), is split between them by
   nearest point.
5. Conflicts and leftovers: a segment outside every core object of two or more segments
   (a split half, a merged blob, a speck) joins the object, or background, that holds most
   of its points in the other views; a segment with no points stays background.
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass

import numpy as np
from scipy import sparse
from scipy.spatial import cKDTree

from dataset_tools.scene import View
from hqmask.association.common import ViewExclusiveUnion, compact_ids
from hqmask.association.flow import pose_order


def _segment_of_points(view: View, seg: np.ndarray, n_points: int) -> np.ndarray:
    """(P,) local segment under each SfM point in this view; -1 where the view does not see it."""
    out = np.full(n_points, -1, np.int64)
    px = np.clip(view.uv.astype(int), 0, [seg.shape[1] - 1, seg.shape[0] - 1])
    out[view.point_ids] = seg[px[:, 1], px[:, 0]]
    return out


def _split_by_points(
    view: View, region: np.ndarray, pts: np.ndarray, objs: np.ndarray, ratio: float, min_points: int
) -> list[tuple[int, np.ndarray]]:
    """[(object, pixel mask)] partitioning ``region`` by the object (-2: background) of the
    nearest SfM point when it has two or more parts; else []. An object is a part when it
    holds ``ratio`` of the segment's object points, background when it holds ``ratio`` of all
    its points (both at least ``min_points``): a mask that bleeds into the floor keeps its
    object however much floor it covers."""
    known = objs != -1
    if ratio <= 0 or known.sum() < 2 * min_points:
        return []
    on_object = known & (objs != -2)
    values, counts = np.unique(objs[on_object], return_counts=True)
    strong = values[(counts >= ratio * on_object.sum()) & (counts >= min_points)]
    n_background = int((objs == -2).sum())
    if n_background >= ratio * known.sum() and n_background >= min_points:
        strong = np.append(strong, -2)
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
    background_vote: float = 0.5,
) -> list[np.ndarray]:
    """Associate segments across views through the SfM points they share (steps 1-5 of the
    module docstring). The views are taken in an order their poses give
    (:func:`hqmask.association.flow.pose_order`), so that ties between equally strong links
    never depend on file names.

    Args:
        views: the views (their ``point_ids`` and ``uv`` observations are used).
        segments: per view, (H, W) int32 segment map (0 = background); not modified.
        n_points: number of SfM points (rows of ``Scene.points``).
        link_ratio: two segments link when each holds this share of the points both views see.
        min_shared: the fewest shared points a link needs.
        split_ratio: a segment is split when two or more objects each hold this share of
            its object points, or an object does and background holds this share of all its
            points (each at least ``min_shared`` points): every pixel goes to the object, or
            background, of its nearest point (a merged or bleeding mask repaired).
            0 disables splitting.
        background_vote: the weight of a view's background against an object's 1 when the
            views vote on a point's object: at 0.5 a point inside an object in more than a
            third of the views that see it belongs to the object (where the masks cut away
            part of a small object in most views, its pixels in the views that saw it whole
            stay its).
    Returns:
        per view, (H, W) uint8 consistent ID map.
    """
    centers = np.stack([v.center for v in views])
    order = pose_order(centers, np.stack([v.cam_from_world[2, :3] for v in views]))
    ids = _associate(
        [views[k] for k in order],
        [segments[k] for k in order],
        n_points,
        link_ratio=link_ratio,
        min_shared=min_shared,
        split_ratio=split_ratio,
        background_vote=background_vote,
    )
    out: list[np.ndarray] = [np.empty(0)] * len(views)
    for k, m in zip(order, ids):
        out[k] = m
    return out


@dataclass
class _Graph:
    """Every segment of every view as a node (each view's background too), and where the SfM
    points fall.

    Attributes:
        seg_at: (V, P) local segment under each point in each view; -1 where the view does not
            see it. node: (V, P) the same as global node numbers. offsets: (V + 1,) first node
            of each view. is_background: (nodes,) bool. view_of: (nodes,) view of each node.
    """

    seg_at: np.ndarray
    node: np.ndarray
    offsets: np.ndarray
    is_background: np.ndarray
    view_of: np.ndarray

    @classmethod
    def of(cls, views: list[View], segments: list[np.ndarray], n_points: int) -> _Graph:
        seg_at = np.stack([_segment_of_points(v, s, n_points) for v, s in zip(views, segments)])
        offsets = np.concatenate([[0], np.cumsum([int(s.max()) + 1 for s in segments])])
        node = np.where(seg_at >= 0, seg_at + offsets[:-1, None], -1)
        is_background = np.zeros(offsets[-1], bool)
        is_background[offsets[:-1]] = True
        return cls(seg_at, node, offsets, is_background, np.repeat(np.arange(len(views)), np.diff(offsets)))

    def links(self, link_ratio: float, min_shared: int) -> list[tuple[int, int, int]]:
        """(shared points, node, node) for every pair of object segments of two views that
        hold most of each other's points seen in both views.

        With M the (nodes, points) incidence of segments and the points they hold, and V the
        (views, points) visibility, M M^T counts the points two segments share and M V^T the
        points of a segment that another view sees: one sparse product each.
        """
        n_views, n_points = self.seg_at.shape
        n_nodes = len(self.view_of)
        views, points = np.nonzero(self.node >= 0)
        nodes = self.node[views, points]
        incidence = sparse.csr_matrix((np.ones(len(nodes)), (nodes, points)), shape=(n_nodes, n_points))
        visible = sparse.csr_matrix((np.ones(len(views)), (views, points)), shape=(n_views, n_points))
        shared = sparse.triu(incidence @ incidence.T, k=1).tocoo()
        seen_by = (incidence @ visible.T).toarray()  # (nodes, views): points of a node seen in a view
        x, y, count = shared.row, shared.col, shared.data
        keep = (
            (self.view_of[x] != self.view_of[y])
            & ~self.is_background[x]
            & ~self.is_background[y]
            & (count >= min_shared)
            & (count >= link_ratio * seen_by[x, self.view_of[y]])
            & (count >= link_ratio * seen_by[y, self.view_of[x]])
        )
        return [(int(c), int(a), int(b)) for c, a, b in zip(count[keep], x[keep], y[keep])]


def _core_objects(graph: _Graph, links: list[tuple[int, int, int]]) -> tuple[np.ndarray, np.ndarray]:
    """Step 2: links taken strongest first into a union-find that never holds two segments of
    one view. Returns each node's root (N,) and whether it belongs to a core object (N,)."""
    union = ViewExclusiveUnion([{int(v)} for v in graph.view_of])
    for _, x, y in sorted(links, key=lambda link: (-link[0], link[1], link[2])):
        union.union(x, y)
    root = union.roots()
    members = defaultdict(int)
    for r in root[~graph.is_background]:
        members[int(r)] += 1
    core = np.array([not graph.is_background[i] and members[int(root[i])] >= 2 for i in range(len(root))])
    return root, core


def _join_pieces(graph: _Graph, root: np.ndarray, core: np.ndarray) -> np.ndarray:
    """Step 3: every core object that is a piece of another takes the whole's root. Returns
    each node's object (N,): a root for core nodes, -1 for the others, -2 for background."""
    obj_of_node = np.where(core, root, -1)
    obj_of_node[graph.is_background] = -2
    whole_of = _pieces(np.where(graph.node >= 0, obj_of_node[np.maximum(graph.node, 0)], -1), np.unique(root[core]))
    root = root.copy()
    for piece in whole_of:
        whole = whole_of[piece]
        while whole in whole_of:  # a piece of a piece (no cycles: a whole is seen in more views)
            whole = whole_of[whole]
        root[root == piece] = whole
    obj_of_node[core] = root[core]
    return obj_of_node


def _point_objects(graph: _Graph, obj_of_node: np.ndarray, background_vote: float) -> dict[int, int]:
    """Each point's object: the weighted majority over the views of the core object it falls
    in (weight 1) or background (-2, weight ``background_vote``); ties to the smaller."""
    votes: dict[int, dict[int, float]] = defaultdict(lambda: defaultdict(float))
    for v in range(len(graph.node)):
        seen = np.flatnonzero(graph.node[v] >= 0)
        for p, o in zip(seen, obj_of_node[graph.node[v, seen]]):
            if o != -1:
                votes[int(p)][int(o)] += background_vote if o == -2 else 1.0
    return {p: max(c.items(), key=lambda kv: (kv[1], -kv[0]))[0] for p, c in votes.items()}


def _label_view(
    view: View,
    seg: np.ndarray,
    v: int,
    graph: _Graph,
    obj_of_node: np.ndarray,
    point_obj: dict[int, int],
    split_ratio: float,
    min_shared: int,
) -> tuple[np.ndarray, np.ndarray]:
    """Steps 4-5 for one view: the global object of each local segment, after splitting the
    segments whose points belong to several objects. Returns the (possibly split) segment
    map and the (n + 1,) objects of its segments (-1: background)."""
    seg = seg.copy()
    g = np.full(int(seg.max()) + 1, -1, np.int64)
    for local in range(1, len(g)):
        pts = np.flatnonzero(graph.seg_at[v] == local)
        objs = np.array([point_obj.get(int(p), -1) for p in pts], np.int64)
        parts = _split_by_points(view, seg == local, pts, objs, split_ratio, min_shared)
        if parts:
            for k, (obj, pixels) in enumerate(parts):
                if k:  # every further part becomes a new local segment
                    seg[pixels] = len(g)
                    g = np.append(g, -1)
                g[local if k == 0 else len(g) - 1] = obj if obj >= 0 else -1
            continue
        obj = obj_of_node[graph.offsets[v] + local]
        if obj >= 0:
            g[local] = obj
            continue
        known = objs[objs != -1]
        if len(known):
            values, counts = np.unique(known, return_counts=True)
            best = values[np.lexsort((-values, counts))[-1]]  # most points, ties to the smaller
            g[local] = best if best >= 0 else -1
    return seg, g


def _associate(
    views: list[View],
    segments: list[np.ndarray],
    n_points: int,
    *,
    link_ratio: float,
    min_shared: int,
    split_ratio: float,
    background_vote: float,
) -> list[np.ndarray]:
    """Steps 1-5 of the module docstring on views in a fixed order."""
    graph = _Graph.of(views, segments, n_points)
    root, core = _core_objects(graph, graph.links(link_ratio, min_shared))
    obj_of_node = _join_pieces(graph, root, core)
    point_obj = _point_objects(graph, obj_of_node, background_vote)
    labelled = [
        _label_view(view, seg, v, graph, obj_of_node, point_obj, split_ratio, min_shared)
        for v, (view, seg) in enumerate(zip(views, segments))
    ]
    return compact_ids([g for _, g in labelled], [seg for seg, _ in labelled])
