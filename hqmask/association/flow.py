"""DEVA-style association along a path through the views: propagate, match, remember, both ways.

The views are visited along a path that depends on their camera poses alone
(:func:`pose_order`), so renaming the files changes nothing. In each direction:

1. the previous view's object masks are carried to the current view by dense optical flow
   (OpenCV DIS, computed from the current view back to the previous one); a track whose
   anchor (see below) is fixed by rays at least ``carry_spread`` degrees apart is carried
   instead along the flow that a plane at its anchor's depth implies, which follows steps
   between views that optical flow cannot (between views close together, as a forward-facing
   capture's, the anchor's depth is too loose for that and the flow is better);
2. the current view's segments are matched to the carried masks by IoU with the Hungarian
   algorithm (IoU >= ``min_iou``), then what is left to the tracks left free at a weaker
   IoU (>= ``weak_iou``: large steps between views move the carried masks off their
   objects) where the segment also shares at least ``reid_colors`` of the track's colour
   histogram (a weak overlap alone may be another object that the carried mask drifted
   onto), two rounds as in ByteTrack;
3. a segment left over that shares at least ``reid_colors`` of its colour histogram with a
   free track (one lost in the last ``memory`` views, or one whose carried mask a large
   step took off its object) is that track seen again (a third Hungarian round);
   The camera poses gate every round: a track seen from two directions has an anchor (see
   below) and matches only a segment whose centroid lies within ``gate`` segment radii of
   where its anchor projects; a track seen once matches only a segment whose centroid ray
   passes within ``gate`` object radii of its own (the epipolar constraint). So a carried
   mask that a large step moved onto a neighbour cannot hand the track over to it;
4. a new track whose segment lies mostly (>= ``contain``) inside a matched object may be a
   piece of it (a split mask); at the end two tracks are one object when the views that
   show them as one (a piece born inside the other, or a segment holding most of the other
   as carried from the view before, each where the poses allow it) are at least as many as
   the views in which both are matched (a split mask, not two objects that one mask merged);
5. tracks without a match are carried on for ``memory`` views.

The forward and backward passes are merged by bidirectional consensus: a forward and a
backward track are the same object when the pixels they share cover at least
``consensus`` of the smaller one; pairs are joined largest overlap first, never joining
groups that hold different segments of one view.

Where the views lie far apart (an orbit of 16 views is 22.5 degrees a step) the flow cannot
follow and an object falls apart into several tracks. The camera poses join them again: each
track's anchor, the point nearest to the rays through its segments' centroids
(:mod:`hqmask.association.anchors`), projects inside the segments of every other track of
its object and lies within the object's size of their anchors. Two tracks that never share a
view are joined when each one's anchor falls in the other's segments in at least
``anchor_inside`` of its views (a track seen once, which has no anchor of its own, when the
other's anchor falls in its segment and their colours agree), nearest anchors first. So are
two tracks handed over at a split mask: where one view gives an object as two pieces, the
propagation may go on with the new piece's ID; such tracks share a few views, in each of which
their segments touch, and are seen together in fewer views than each is seen alone.
Tracks seen in fewer than ``min_views`` views are dropped.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

import cv2
import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.sparse.csgraph import minimum_spanning_tree, shortest_path

from dataset_tools.cameras import CameraPose
from hqmask.association.anchors import Anchor, Sighting, project, rays_meet, sighting, triangulate
from hqmask.association.common import ViewExclusiveUnion, compact_ids
from hqmask.optical_flow import flow_between, pull_along_plane, pull_labels


def pose_distances(centers: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """(V, V) distances between camera poses: centre distance in units of the median distance
    to the nearest other camera, plus the angle between viewing directions in radians."""
    gap = np.linalg.norm(centers[:, None] - centers[None], axis=-1)
    others = gap + np.diag(np.full(len(centers), np.inf))
    scale = float(np.median(others.min(axis=1))) if len(centers) > 1 else 1.0
    angle = np.arccos(np.clip(directions @ directions.T, -1.0, 1.0))
    return gap / max(scale, 1e-12) + angle


def pose_order(centers: np.ndarray, directions: np.ndarray) -> list[int]:
    """A path through the views that depends on their poses alone, with no long step: it
    starts at an end of the longest path of the poses' minimum spanning tree, goes to the
    nearest unvisited view each time (ties broken by the camera centres' coordinates, never
    by file order), then 2-opt reversals shorten it until no reversal lowers the sum of its
    squared steps (a greedy walk through a spiral of views jumps between the arms at its end).

    Args:
        centers: (V, 3) camera centres. directions: (V, 3) unit viewing directions.
    """
    n = len(centers)
    if n <= 2:
        return sorted(range(n), key=lambda k: tuple(centers[k]))
    dist = pose_distances(centers, directions)
    hops = shortest_path(minimum_spanning_tree(dist), directed=False)
    a = int(np.argmax(hops[int(np.argmin(centers[:, 0]))]))
    b = int(np.argmax(hops[a]))
    order = [min(a, b, key=lambda k: tuple(centers[k]))]
    left = set(range(n)) - set(order)
    while left:
        last = order[-1]
        nxt = min(left, key=lambda k: (dist[last, k], tuple(centers[k])))
        order.append(nxt)
        left.remove(nxt)
    return _two_opt(order, dist**2)


def _two_opt(order: list[int], cost: np.ndarray) -> list[int]:
    """``order`` with segments reversed while that lowers the summed ``cost`` (V, V) of its
    steps. The path is closed through a dummy stop that costs nothing to reach or leave, so
    its ends may move too; the first improving reversal is taken each time (deterministic)."""
    n = len(order)
    full = np.zeros((n + 1, n + 1))
    full[:n, :n] = cost
    tour = np.array(order + [n])  # the dummy stop closes the path into a tour
    improved = True
    while improved:
        improved = False
        for i in range(n - 1):
            a, b = tour[i], tour[i + 1]
            c, d = tour[i + 2 :], np.roll(tour, -1)[i + 2 :]
            gain = full[a, b] + full[c, d] - full[a, c] - full[b, d]
            best = int(np.argmax(gain))
            if gain[best] > 1e-12:
                j = i + 2 + best
                tour[i + 1 : j + 1] = tour[i + 1 : j + 1][::-1]
                improved = True
    k = int(np.flatnonzero(tour == n)[0])
    return [int(x) for x in np.roll(tour, -k)[1:]]


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


@dataclass(frozen=True)
class FlowOptions:
    """The thresholds of :func:`associate_flow` (see the module docstring)."""

    min_iou: float = 0.3
    weak_iou: float = 0.1
    contain: float = 0.6
    memory: int = 5
    reid_colors: float = 0.5
    consensus: float = 0.3
    anchor_inside: float = 0.5
    gate: float = 1.5
    carry_spread: float = 10.0
    min_views: int = 2


@dataclass
class _ViewMatch:
    """One view's segments against the tracks carried into it."""

    segments: np.ndarray  # (H, W) local segment numbers
    area: np.ndarray  # (n + 1,) pixels of each segment
    hist: np.ndarray  # (n + 1, 512) colour histograms
    track_ids: list[int]  # the tracks carried in, in column order
    inter: np.ndarray  # (n + 1, T) pixels each segment shares with each carried track
    track_area: np.ndarray  # (T,)
    allowed: np.ndarray  # (n, T) bool: the track's anchor, where it has one, projects near the segment

    @property
    def iou(self) -> np.ndarray:
        """(n, T) IoU of the segments 1..n with the carried tracks."""
        return self.inter[1:] / np.maximum(self.area[1:, None] + self.track_area[None] - self.inter[1:], 1)


@dataclass
class _Pass:
    """Propagation along ``order`` in one direction (steps 1-5 of the module docstring)."""

    images: list[np.ndarray]
    segments: list[np.ndarray]
    views: list[CameraPose]
    options: FlowOptions
    tracks: dict[int, _Track] = field(default_factory=dict)
    sightings: dict[int, list[Sighting]] = field(default_factory=dict)
    anchors: dict[int, Anchor | None] = field(default_factory=dict)  # of the sightings so far
    together: Counter = field(default_factory=Counter)  # track pair -> views with evidence of one object
    next_id: int = 0

    def run(self, order: list[int]) -> list[np.ndarray]:
        """Per view, (n_v + 1,) int64 track of each local segment (-1: none)."""
        track_of: list[np.ndarray | None] = [None] * len(self.segments)
        prev = None
        for v in order:
            if prev is not None and self.tracks:
                self._carry(v, prev)
            view = self._overlaps(v)
            assign = np.full(len(view.area), -1, np.int64)
            inside = self._match(view, assign) if view.track_ids and len(view.area) > 1 else {}
            self._new_tracks(view, assign, inside)
            self._note_holders(view, assign)
            self._remember(v, view, assign)
            track_of[v] = assign
            prev = v
        return self._join_pieces(track_of)

    def _carry(self, v: int, prev: int) -> None:
        """Step 1: the tracks' masks, carried from view ``prev`` into view ``v``."""
        view, before = self.views[v], self.views[prev]
        H, W = self.segments[v].shape
        flow = None
        for t, track in self.tracks.items():
            anchor = self.anchors.get(t)
            firm = anchor is not None and anchor.spread >= np.deg2rad(self.options.carry_spread)
            depth = anchor.point @ view.cam_from_world[2, :3] + view.cam_from_world[2, 3] if firm else None
            if depth is not None and depth > 0:
                track.mask = pull_along_plane(track.mask, view, before, depth, (H, W))
                continue
            if flow is None:
                flow = flow_between(self.images[v], self.images[prev])
            track.mask = pull_labels(track.mask, flow)

    def _overlaps(self, v: int) -> _ViewMatch:
        seg = self.segments[v]
        n = int(seg.max())
        ids = list(self.tracks)
        inter = np.zeros((n + 1, len(ids)))
        for j, t in enumerate(ids):
            inter[:, j] = np.bincount(seg[self.tracks[t].mask > 0], minlength=n + 1)
        area = np.bincount(seg.ravel(), minlength=n + 1).astype(float)
        return _ViewMatch(
            seg,
            area,
            _color_histograms(self.images[v], seg, n),
            ids,
            inter,
            np.array([float(np.count_nonzero(self.tracks[t].mask)) for t in ids]),
            self._allowed(v, seg, area, ids),
        )

    def _allowed(self, v: int, seg: np.ndarray, area: np.ndarray, ids: list[int]) -> np.ndarray:
        """(n, T) bool: where segment ``i + 1`` agrees with the poses of track ``ids[j]``: near
        where its anchor projects, or (a track seen once) on a ray that meets its ray."""
        n = len(area) - 1
        allowed = np.ones((n, len(ids)), bool)
        if not n:
            return allowed
        rows, cols = np.indices(seg.shape)
        count = np.maximum(area[1:], 1)
        center = np.stack(
            [
                np.bincount(seg.ravel(), rows.ravel(), n + 1)[1:] / count,
                np.bincount(seg.ravel(), cols.ravel(), n + 1)[1:] / count,
            ],
            1,
        )
        radius = np.sqrt(count / np.pi)
        view = self.views[v]
        here = [sighting(v, seg == i + 1, view.camera, view.cam_from_world) if area[i + 1] else None for i in range(n)]
        for j, t in enumerate(ids):
            anchor = self.anchors.get(t)
            if anchor is None:
                seen = self.sightings.get(t, [])
                if len(seen) == 1:
                    allowed[:, j] = [s is not None and rays_meet(seen[0], s, self.options.gate) for s in here]
                continue
            x = view.cam_from_world[:, :3] @ anchor.point + view.cam_from_world[:, 3]
            if x[2] <= 0:
                allowed[:, j] = False
                continue
            pixel = np.array(
                [view.camera.fy * x[1] / x[2] + view.camera.cy, view.camera.fx * x[0] / x[2] + view.camera.cx]
            )
            allowed[:, j] = np.linalg.norm(center + 0.5 - pixel, axis=1) <= self.options.gate * radius
        return allowed

    def _match(self, view: _ViewMatch, assign: np.ndarray) -> dict[int, int]:
        """Steps 2-3: three Hungarian rounds; fills ``assign``. Returns the unmatched segments
        lying inside a matched track (step 4): {segment: track}."""
        o = self.options
        ids, iou = view.track_ids, np.where(view.allowed, view.iou, 0.0)
        local = np.arange(1, len(view.area))
        for r, c in zip(*linear_sum_assignment(-iou)):
            if iou[r, c] >= o.min_iou:
                assign[local[r]] = ids[c]
        matched = {int(assign[local_id]) for local_id in local if assign[local_id] >= 0}
        left = [r for r, local_id in enumerate(local) if assign[local_id] < 0 and view.area[local_id] > 0]
        free = [j for j, t in enumerate(ids) if t not in matched]
        if left and free:
            # colours shared between each leftover segment and each free track
            profile = view.hist[local[left]] / view.area[local[left], None]
            colors = np.minimum(profile[:, None], np.stack([self.tracks[ids[j]].colors for j in free])[None]).sum(-1)
            colors = np.where(view.allowed[np.ix_(left, free)], colors, 0.0)
            # second round: a weaker overlap, confirmed by the colours; third, re-identification
            # by the colours alone (the carried mask of a track lost a while ago, or moved far
            # by a large step, is off its object)
            weak = np.where(colors >= o.reid_colors, iou[np.ix_(left, free)], 0.0)
            for score, floor in ((weak, o.weak_iou), (colors, o.reid_colors)):
                rows = [r for r in range(len(left)) if assign[local[left[r]]] < 0]
                cols = [c for c in range(len(free)) if ids[free[c]] not in matched]
                sub = score[np.ix_(rows, cols)]
                for r, c in zip(*linear_sum_assignment(-sub)):
                    if sub[r, c] >= floor:
                        assign[local[left[rows[r]]]] = ids[free[cols[c]]]
                        matched.add(ids[free[cols[c]]])
        inside = {}
        for r in left:
            local_id = local[r]
            share = view.inter[local_id] / view.area[local_id]
            j = int(np.argmax(share))
            if assign[local_id] < 0 and share[j] >= o.contain and ids[j] in matched and view.allowed[r, j]:
                inside[int(local_id)] = ids[j]
        return inside

    def _new_tracks(self, view: _ViewMatch, assign: np.ndarray, inside: dict[int, int]) -> None:
        """Step 4: every segment left unmatched starts a track; a piece born inside a matched
        track counts as one view showing the two as one."""
        for local_id in range(1, len(view.area)):
            if assign[local_id] < 0 and view.area[local_id] > 0:
                assign[local_id] = self.next_id
                if local_id in inside:
                    self.together[(inside[local_id], self.next_id)] += 1
                self.next_id += 1

    def _note_holders(self, view: _ViewMatch, assign: np.ndarray) -> None:
        """Step 4: a segment holding most of a track seen in the last view, unmatched here,
        shows the two tracks as one."""
        if not view.track_ids or len(view.area) <= 1:
            return
        here = {int(a) for a in assign[1:] if a >= 0}
        share = view.inter[1:] / np.maximum(view.track_area[None], 1)
        for r, local_id in enumerate(range(1, len(view.area))):
            if assign[local_id] < 0:
                continue
            for j in np.flatnonzero((share[r] >= self.options.contain) & view.allowed[r]):
                t = view.track_ids[j]
                if t not in here and self.tracks[t].age == 0:
                    self.together[(min(t, int(assign[local_id])), max(t, int(assign[local_id])))] += 1

    def _remember(self, v: int, view: _ViewMatch, assign: np.ndarray) -> None:
        """Step 5: matched tracks take this view's masks and colours; the others age and are
        forgotten after ``memory`` views."""
        for track in self.tracks.values():
            track.age += 1
        for t in {int(a) for a in assign[1:] if a >= 0}:
            mine = np.flatnonzero(assign == t)
            colors = view.hist[mine].sum(0)
            mask = np.isin(view.segments, mine)
            self.tracks[t] = _Track(mask.astype(np.uint8), colors / max(colors.sum(), 1.0))
            self.sightings.setdefault(t, []).append(
                sighting(v, mask, self.views[v].camera, self.views[v].cam_from_world)
            )
            self.anchors[t] = triangulate(self.sightings[t])
        for t in [t for t, tr in self.tracks.items() if tr.age > self.options.memory]:
            del self.tracks[t]

    def _join_pieces(self, track_of: list[np.ndarray]) -> list[np.ndarray]:
        """Two tracks are one object when the views that show them as one are at least as
        many as those that show them apart (both matched in one view): a mask split in a few
        views, not two objects a mask merged."""
        views_of: list[set[int]] = [set() for _ in range(self.next_id)]
        for v, a in enumerate(track_of):
            for t in np.unique(a[a >= 0]):
                views_of[t].add(v)
        union = ViewExclusiveUnion(views_of)
        for (a, b), n in sorted(self.together.items(), key=lambda kv: (-kv[1], kv[0])):
            union.union(a, b, tolerate=n)
        final = union.roots()
        return [np.where(a >= 0, final[np.maximum(a, 0)], -1) for a in track_of]


def _merge_passes(
    forward: list[np.ndarray], backward: list[np.ndarray], segments: list[np.ndarray], consensus: float
) -> list[np.ndarray]:
    """Bidirectional consensus: forward and backward tracks sharing at least ``consensus`` of
    the smaller one's pixels are one object, largest overlap first, never two segments of one
    view in one object. Returns per view the (n_v + 1,) merged track of each local segment."""
    n_f = 1 + max((int(a.max()) for a in forward), default=0)
    n_b = 1 + max((int(a.max()) for a in backward), default=0)
    overlap = np.zeros((n_f, n_b), np.int64)
    for f, b, seg in zip(forward, backward, segments):
        area = np.bincount(seg.ravel(), minlength=len(f))
        ok = (f >= 0) & (b >= 0)
        ok[0] = False
        np.add.at(overlap, (f[ok], b[ok]), area[ok])
    size_f, size_b = overlap.sum(1), overlap.sum(0)
    # forward tracks carry views 0..V-1, backward tracks V..2V-1: two tracks of one pass that
    # hold different segments of one view are never joined
    views: list[set[int]] = [set() for _ in range(n_f + n_b)]
    n_views = len(forward)
    for v, (f, b) in enumerate(zip(forward, backward)):
        for t in np.unique(f[1:][f[1:] >= 0]):
            views[t].add(v)
        for t in np.unique(b[1:][b[1:] >= 0]):
            views[n_f + t].add(n_views + v)
    union = ViewExclusiveUnion(views)
    for i, j in sorted(zip(*np.nonzero(overlap)), key=lambda ij: (-overlap[ij], ij)):
        if overlap[i, j] >= consensus * min(size_f[i], size_b[j]):
            union.union(int(i), n_f + int(j))
    root = union.roots()[:n_f]
    merged = [np.where(f >= 0, root[np.maximum(f, 0)], -1) for f in forward]
    for g in merged:
        g[0] = -1
    return merged


@dataclass
class _TrackViews:
    """A track's masks by view, its anchor (None when it has none) and colour profile."""

    masks: dict[int, np.ndarray]
    anchor: Anchor | None
    colors: np.ndarray

    def holds(self, point: np.ndarray, views: list[CameraPose]) -> float:
        """The share of this track's views in which ``point`` falls inside its mask."""
        hits = 0
        for v, mask in self.masks.items():
            pixel = project(point, views[v].camera, views[v].cam_from_world)
            hits += pixel is not None and bool(mask[pixel])
        return hits / len(self.masks)


def _track_views(
    tracks_of: list[np.ndarray], segments: list[np.ndarray], images: list[np.ndarray], views: list[CameraPose]
) -> dict[int, _TrackViews]:
    found: dict[int, _TrackViews] = {}
    for v, (g, seg) in enumerate(zip(tracks_of, segments)):
        hist = _color_histograms(images[v], seg, len(g) - 1)
        for t in np.unique(g[g >= 0]):
            mine = np.flatnonzero(g == t)
            entry = found.setdefault(int(t), _TrackViews({}, None, np.zeros(512)))
            entry.masks[v] = np.isin(seg, mine)
            colors = hist[mine].sum(0)
            entry.colors += colors / max(colors.sum(), 1.0)
    for entry in found.values():
        entry.colors /= len(entry.masks)
        entry.anchor = triangulate(
            [sighting(v, m, views[v].camera, views[v].cam_from_world) for v, m in entry.masks.items()]
        )
    return found


def _handed_over(a: _TrackViews, b: _TrackViews, shared: set[int]) -> bool:
    """Whether two tracks seen together in the views ``shared`` may be one object handed over
    at a split mask: they are apart in fewer views than each is seen without the other, and
    in every view they share their masks touch (the two pieces of one split segment)."""
    alone = min(len(a.masks), len(b.masks)) - len(shared)
    return len(shared) < alone and all(_touch(a.masks[v], b.masks[v]) for v in shared)


def _touch(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether the (H, W) bool masks ``a`` and ``b`` are 8-neighbours somewhere."""
    grown = cv2.dilate(a.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
    return bool(np.any(grown & b))


def _join_by_anchors(
    tracks_of: list[np.ndarray],
    segments: list[np.ndarray],
    images: list[np.ndarray],
    views: list[CameraPose],
    options: FlowOptions,
) -> list[np.ndarray]:
    """Tracks of one object that the flow could not link, joined by their anchors (see the
    module docstring). Returns per view the (n_v + 1,) joined track of each local segment."""
    tracks = _track_views(tracks_of, segments, images, views)
    ids = sorted(tracks)
    pairs = []
    for i, a in enumerate(ids):
        for b in ids[i + 1 :]:
            ta, tb = tracks[a], tracks[b]
            if ta.anchor is None and tb.anchor is None:
                continue
            shared = ta.masks.keys() & tb.masks.keys()
            if shared and not _handed_over(ta, tb, shared):
                continue
            if ta.anchor is not None and tb.anchor is not None:
                gap = np.linalg.norm(ta.anchor.point - tb.anchor.point) / max(ta.anchor.radius, tb.anchor.radius)
                if (
                    gap <= 1.0
                    and min(tb.holds(ta.anchor.point, views), ta.holds(tb.anchor.point, views)) >= options.anchor_inside
                ):
                    pairs.append((gap, len(shared), a, b))
                continue
            seen_once, anchored = (ta, tb) if ta.anchor is None else (tb, ta)
            colors = np.minimum(seen_once.colors, anchored.colors).sum()
            if seen_once.holds(anchored.anchor.point, views) == 1.0 and colors >= options.reid_colors:
                pairs.append((1.0, 0, a, b))
    union = ViewExclusiveUnion([set(tracks[t].masks) for t in ids])
    index = {t: k for k, t in enumerate(ids)}
    for _, shared_views, a, b in sorted(pairs):
        union.union(index[a], index[b], tolerate=shared_views)
    root = union.roots()
    joined = np.full(max(ids, default=-1) + 1, -1, np.int64)
    joined[ids] = [ids[r] for r in root]
    return [np.where(g >= 0, joined[np.maximum(g, 0)], -1) for g in tracks_of]


def _drop_rare(tracks_of: list[np.ndarray], min_views: int) -> list[np.ndarray]:
    """Tracks seen in fewer than ``min_views`` views become background."""
    seen = [np.unique(g[g >= 0]) for g in tracks_of]
    views_of = np.bincount(np.concatenate(seen), minlength=1) if seen else np.zeros(1, np.int64)
    return [np.where((g >= 0) & (views_of[np.maximum(g, 0)] >= min_views), g, -1) for g in tracks_of]


def associate_flow(
    images: list[np.ndarray],
    segments: list[np.ndarray],
    views: list[CameraPose],
    options: FlowOptions = FlowOptions(),
) -> list[np.ndarray]:
    """Associate segments along a path through the views with optical flow, forwards and
    backwards, and join what the flow could not link by the camera poses.

    Args:
        images: per view, (H, W, 3) uint8 RGB (for the optical flow); views may differ in size.
        segments: per view, (H, W) int32 segment map (0 = background).
        views: per view, its camera and pose (a scene's ``View`` or a ``CameraPose``), with
            the images' sizes.
    Returns:
        per view, (H, W) uint8 consistent ID map.
    """
    centers = np.stack([-v.cam_from_world[:, :3].T @ v.cam_from_world[:, 3] for v in views])
    order = pose_order(centers, np.stack([v.cam_from_world[2, :3] for v in views]))
    forward = _Pass(images, segments, views, options).run(order)
    backward = _Pass(images, segments, views, options).run(order[::-1])
    merged = _merge_passes(forward, backward, segments, options.consensus)
    joined = _join_by_anchors(merged, segments, images, views, options)
    return compact_ids(_drop_rare(joined, options.min_views), segments)
