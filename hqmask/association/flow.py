"""DEVA-style association for video-like sequences: propagate, match, remember, both ways.

Views are ordered as a sequence (a nearest-neighbour path through the camera centres when
poses exist, else file order). In each direction:

1. the previous view's object masks are carried to the current view by dense optical flow
   (OpenCV DIS, computed from the current view back to the previous one);
2. the current view's segments are matched to the carried masks by IoU with the Hungarian
   algorithm (IoU >= ``min_iou``), then what is left to the tracks left free at a weaker
   IoU (>= ``weak_iou``: large steps between views move the carried masks off their
   objects) where the segment also shares at least ``reid_colors`` of the track's colour
   histogram (a weak overlap alone may be another object that the carried mask drifted
   onto), two rounds as in ByteTrack;
3. a segment left over that shares at least ``reid_colors`` of its colour histogram with a
   free track (one lost in the last ``memory`` views, or one whose carried mask a large
   step took off its object) is that track seen again (a third Hungarian round);
4. a new track whose segment lies mostly (>= ``contain``) inside a matched object may be a
   piece of it (a split mask); at the end two tracks are one object when the views that
   show them as one (a piece born inside the other, or a segment holding most of the other
   as carried from the view before) are at least as many as the views in which both are
   matched (a split mask, not two objects that one mask merged);
5. tracks without a match are carried on for ``memory`` views.

The forward and backward passes are merged by bidirectional consensus: a forward and a
backward track are the same object when the pixels they share cover at least
``consensus`` of the smaller one; pairs are joined largest overlap first, never joining
groups that hold different segments of one view. Tracks seen in fewer than ``min_views``
views are dropped.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

from hqmask.association.common import ViewExclusiveUnion, compact_ids
from hqmask.optical_flow import flow_between, pull_labels


def sequence_order(centers: np.ndarray | None, n: int) -> list[int]:
    """Visit order: greedy nearest-neighbour path through camera centres (N, 3) from view 0."""
    if centers is None:
        return list(range(n))
    order, left = [0], set(range(1, n))
    while left:
        last = centers[order[-1]]
        nxt = min(left, key=lambda k: (float(np.sum((centers[k] - last) ** 2)), k))
        order.append(nxt)
        left.remove(nxt)
    return order


@dataclass
class _Track:
    mask: np.ndarray  # (H, W) uint8, in the latest view
    colors: np.ndarray  # (512,) colour histogram where it was last seen, summing to 1
    age: int = 0


def _color_histograms(image: np.ndarray, seg: np.ndarray, n: int) -> np.ndarray:
    """(n + 1, 512) pixel counts of each segment over 8 levels a channel. image (H, W, 3) uint8."""
    q = image.astype(np.int64) // 32
    bins = seg.astype(np.int64) * 512 + q[..., 0] * 64 + q[..., 1] * 8 + q[..., 2]
    return np.bincount(bins.ravel(), minlength=(n + 1) * 512).reshape(n + 1, 512).astype(float)


def _run_pass(
    order: list[int],
    images: list[np.ndarray],
    segments: list[np.ndarray],
    *,
    min_iou: float,
    weak_iou: float,
    contain: float,
    memory: int,
    reid_colors: float,
) -> list[np.ndarray]:
    track_of: list[np.ndarray | None] = [None] * len(segments)
    tracks: dict[int, _Track] = {}
    together: Counter[tuple[int, int]] = Counter()  # track pair -> views with evidence of one object
    next_id = 0
    prev = None
    for v in order:
        seg = segments[v]
        n_local = int(seg.max())
        assign = np.full(n_local + 1, -1, np.int64)
        inside: dict[int, int] = {}  # unmatched segment -> the matched track it lies in
        if prev is not None and tracks:
            flow = flow_between(images[v], images[prev])
            for t in tracks.values():
                t.mask = pull_labels(t.mask, flow)
        ids = list(tracks)
        local = np.arange(1, n_local + 1)
        seg_area = np.bincount(seg.ravel(), minlength=n_local + 1).astype(float)
        hist = _color_histograms(images[v], seg, n_local)
        if ids and n_local:
            # intersection of every (segment, track) pair
            inter = np.zeros((n_local + 1, len(ids)))
            for j, t in enumerate(ids):
                inter[:, j] = np.bincount(seg[tracks[t].mask > 0], minlength=n_local + 1)
            trk_area = np.array([float(np.count_nonzero(tracks[t].mask)) for t in ids])
            iou = inter[1:] / np.maximum(seg_area[1:, None] + trk_area[None] - inter[1:], 1)
            rows, cols = linear_sum_assignment(-iou)
            for r, c in zip(rows, cols):
                if iou[r, c] >= min_iou:
                    assign[local[r]] = ids[c]
            matched = {int(assign[l]) for l in local if assign[l] >= 0}
            left = [r for r, l in enumerate(local) if assign[l] < 0 and seg_area[l] > 0]
            free = [j for j, t in enumerate(ids) if t not in matched]
            if left and free:
                # colours shared between each leftover segment and each free track
                profile = hist[local[left]] / seg_area[local[left], None]
                colors = np.minimum(profile[:, None], np.stack([tracks[ids[j]].colors for j in free])[None]).sum(-1)
                # second round: a weaker overlap, confirmed by the colours
                weak = np.where(colors >= reid_colors, iou[np.ix_(left, free)], 0.0)
                # third round, re-identification: the colours alone (the carried mask of a
                # track lost a while ago, or moved far by a large step, is off its object)
                for score, floor in ((weak, weak_iou), (colors, reid_colors)):
                    rows = [r for r in range(len(left)) if assign[local[left[r]]] < 0]
                    cols = [c for c in range(len(free)) if ids[free[c]] not in matched]
                    sub = score[np.ix_(rows, cols)]
                    for r, c in zip(*linear_sum_assignment(-sub)):
                        if sub[r, c] >= floor:
                            assign[local[left[rows[r]]]] = ids[free[cols[c]]]
                            matched.add(ids[free[cols[c]]])
            for r in left:  # a piece lying in a matched object: a provisional track of its own
                l = local[r]
                frac = inter[l] / seg_area[l]
                j = int(np.argmax(frac))
                if assign[l] < 0 and frac[j] >= contain and ids[j] in matched:
                    inside[l] = ids[j]
        for l in local:
            if assign[l] < 0 and seg_area[l] > 0:
                assign[l] = next_id
                if l in inside:  # a piece born inside a matched track
                    together[(inside[l], next_id)] += 1
                next_id += 1
        if ids and n_local:  # a segment holding most of a track seen in the last view, unmatched here
            here = {int(a) for a in assign[1:] if a >= 0}
            share = inter[1:] / np.maximum(trk_area[None], 1)
            for r, l in enumerate(local):
                for j in np.flatnonzero(share[r] >= contain) if assign[l] >= 0 else ():
                    if ids[j] not in here and tracks[ids[j]].age == 0:
                        together[(min(ids[j], int(assign[l])), max(ids[j], int(assign[l])))] += 1
        for t in list(tracks):
            tracks[t].age += 1
        for t in set(int(a) for a in assign[1:] if a >= 0):
            mine = np.flatnonzero(assign == t)
            colors = hist[mine].sum(0)
            tracks[t] = _Track(np.isin(seg, mine).astype(np.uint8), colors / max(colors.sum(), 1.0))
        for t in [t for t, tr in tracks.items() if tr.age > memory]:
            del tracks[t]
        track_of[v] = assign
        prev = v
    # Two tracks are one object when the views that show them as one (a piece born inside the
    # other, or one segment holding both) are at least as many as those that show them apart
    # (both matched in one view): a mask split in a few views, not two objects a mask merged.
    views_of: list[set[int]] = [set() for _ in range(next_id)]
    for v, a in enumerate(track_of):
        for t in np.unique(a[a >= 0]):
            views_of[t].add(v)
    uf = ViewExclusiveUnion(views_of)
    for (a, b), n in sorted(together.items(), key=lambda kv: (-kv[1], kv[0])):
        uf.union(a, b, tolerate=n)
    final = uf.roots()
    return [np.where(a >= 0, final[np.maximum(a, 0)], -1) for a in track_of]


def associate_flow(
    images: list[np.ndarray],
    segments: list[np.ndarray],
    centers: np.ndarray | None = None,
    *,
    min_iou: float = 0.3,
    weak_iou: float = 0.1,
    contain: float = 0.6,
    memory: int = 5,
    reid_colors: float = 0.5,
    consensus: float = 0.3,
    min_views: int = 2,
) -> list[np.ndarray]:
    """Associate segments along a sequence with optical flow, forwards and backwards.

    Args:
        images: per view, (H, W, 3) uint8 RGB (for the optical flow).
        segments: per view, (H, W) int32 segment map (0 = background).
        centers: (V, 3) camera centres, or None to use the given order.
    Returns:
        per view, (H, W) uint8 consistent ID map.
    """
    order = sequence_order(centers, len(images))
    kw = dict(min_iou=min_iou, weak_iou=weak_iou, contain=contain, memory=memory, reid_colors=reid_colors)
    fwd = _run_pass(order, images, segments, **kw)
    bwd = _run_pass(order[::-1], images, segments, **kw)
    n_f = 1 + max((int(a.max()) for a in fwd), default=0)
    n_b = 1 + max((int(a.max()) for a in bwd), default=0)
    overlap = np.zeros((n_f, n_b), np.int64)
    for f, b, seg in zip(fwd, bwd, segments):
        area = np.bincount(seg.ravel(), minlength=len(f))
        ok = (f >= 0) & (b >= 0)
        ok[0] = False
        np.add.at(overlap, (f[ok], b[ok]), area[ok])
    size_f, size_b = overlap.sum(1), overlap.sum(0)
    # forward tracks carry views 0..V-1, backward tracks V..2V-1: two tracks of one pass that
    # hold different segments of one view are never joined
    views: list[set[int]] = [set() for _ in range(n_f + n_b)]
    V = len(fwd)
    for v, (f, b) in enumerate(zip(fwd, bwd)):
        for t in np.unique(f[1:][f[1:] >= 0]):
            views[t].add(v)
        for t in np.unique(b[1:][b[1:] >= 0]):
            views[n_f + t].add(V + v)
    uf = ViewExclusiveUnion(views)
    for i, j in sorted(zip(*np.nonzero(overlap)), key=lambda ij: (-overlap[ij], ij)):
        if overlap[i, j] >= consensus * min(size_f[i], size_b[j]):
            uf.union(int(i), n_f + int(j))
    root = uf.roots()[:n_f]
    global_of = [np.where(f >= 0, root[np.maximum(f, 0)], -1) for f in fwd]
    for g in global_of:
        g[0] = -1
    views_of = np.bincount(np.concatenate([np.unique(g[g >= 0]) for g in global_of]), minlength=n_f + n_b)
    global_of = [np.where((g >= 0) & (views_of[np.maximum(g, 0)] >= min_views), g, -1) for g in global_of]
    return compact_ids(global_of, segments)
