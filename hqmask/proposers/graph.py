"""The ``graph`` proposer, weight-free and the default.

Felzenszwalb's graph segmentation, regions merged by mean colour on a region adjacency graph
(:func:`merge_by_mean_colour`), and background removed: regions that touch the image border,
and regions whose colour is close to a large border region (a tiled floor whose inner tiles
do not reach the border), are background. Adjacent foreground regions of similar hue are
joined into one object. Given the view's depth (a first 3D-GS pass rendered, ``hqmask build
--depth``), regions are first cut where the depth jumps and never joined across a jump
(:mod:`hqmask.occlusions`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from dataset_tools.scene import View
from hqmask.occlusions import DepthJumps, cut_at_edges, depth_jumps
from hqmask.proposers.base import Proposals
from hqmask.support_plane import Heights


def _in_front(seg: np.ndarray, occluding: np.ndarray, share: float) -> np.ndarray:
    """(n,) bool: regions of ``seg`` (H, W) that hold pixels on the near side of a depth jump
    (``occluding`` (H, W) bool) for at least ``share`` of their outline's length."""
    n = int(seg.max()) + 1
    outline = ndimage.grey_erosion(seg, size=3) != ndimage.grey_dilation(seg, size=3)
    return np.bincount(seg[occluding], minlength=n) >= share * np.maximum(np.bincount(seg[outline], minlength=n), 1)


def _median_heights(seg: np.ndarray, height: np.ndarray) -> np.ndarray:
    """(n,) each region of ``seg``'s median height above the support plane (``height`` (H, W),
    NaN where nothing is seen, -inf beyond the scene's reach); NaN where it sees nothing."""
    seen = ~np.isnan(height)
    n = int(seg.max()) + 1
    return np.asarray(ndimage.median(np.where(seen, height, 0.0), np.where(seen, seg, -1), np.arange(n)), float)


def _backed(seg: np.ndarray, counts: np.ndarray, observed: np.ndarray, share: float) -> np.ndarray:
    """(n,) bool: regions of ``seg`` (H, W) whose SfM observations (``observed`` (H, W) bool,
    of ``counts`` (n,) pixels each) are at least ``share`` of the view's mean density; all of
    them where the view observes none."""
    n = len(counts)
    return np.bincount(seg[observed], minlength=n) >= share * observed.mean() * counts


def _contact(height: np.ndarray, level: float) -> np.ndarray:
    """(H, W) bool: the line where the surface rises past ``level`` above the support plane
    (``height`` (H, W), NaN or -inf where there is none): pixels on either side of it."""
    rises = np.nan_to_num(height, nan=0.0, neginf=0.0) >= level
    return ndimage.binary_dilation(rises) & ~ndimage.binary_erosion(rises, border_value=1)


def _touching(seg: np.ndarray, edges: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Unique pairs (a < b) of region labels that touch (4-neighbourhood), where neither
    pixel of the touching pair lies on ``edges`` (H, W) bool, when given. Returns the pairs
    (M, 2) and how many pixel pairs touch (M,)."""
    free = np.ones(seg.shape, bool) if edges is None else ~edges
    across, down = free[:, :-1] & free[:, 1:], free[:-1] & free[1:]
    p = np.concatenate(
        [np.stack([seg[:, :-1][across], seg[:, 1:][across]], 1), np.stack([seg[:-1][down], seg[1:][down]], 1)]
    )
    p = np.sort(p[p[:, 0] != p[:, 1]], axis=1)
    return np.unique(p, axis=0, return_counts=True)


def _region_means(seg: np.ndarray, colours: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each region's pixel count (n,) float and mean colour (n, C) over a region map (H, W)
    of labels 0..n-1 and ``colours`` (H, W, C); an empty label has mean 0."""
    n = int(seg.max()) + 1
    counts = np.bincount(seg.ravel(), minlength=n).astype(float)
    sums = np.stack([np.bincount(seg.ravel(), colours[..., c].ravel(), n) for c in range(colours.shape[-1])], 1)
    return counts, sums / np.maximum(counts, 1)[:, None]


def merge_by_mean_colour(segments: np.ndarray, colours: np.ndarray, threshold: float) -> np.ndarray:
    """Regions of ``segments`` (H, W) joined where two that touch (8-neighbourhood) have mean
    ``colours`` (H, W, C) less than ``threshold`` apart, and so on transitively. The result is
    scikit-image's ``graph.cut_threshold(segments, graph.rag_mean_color(colours, segments),
    threshold)``, label for label, computed with array operations where scikit-image builds
    its graph with a Python callback per pixel.

    Returns:
        (H, W) int64 region map.
    """
    _, seg = np.unique(segments, return_inverse=True)
    seg = seg.reshape(segments.shape)
    n = int(seg.max()) + 1
    mean = _region_means(seg, colours)[1]
    a = np.concatenate([seg[:, :-1].ravel(), seg[:-1].ravel(), seg[:-1, :-1].ravel(), seg[:-1, 1:].ravel()])
    b = np.concatenate([seg[:, 1:].ravel(), seg[1:].ravel(), seg[1:, 1:].ravel(), seg[1:, :-1].ravel()])
    pairs = np.unique(np.sort(np.stack([a, b], 1)[a != b], axis=1), axis=0)
    close = np.linalg.norm(mean[pairs[:, 0]] - mean[pairs[:, 1]], axis=1) < threshold
    graph = coo_matrix((np.ones(int(close.sum())), (pairs[close, 0], pairs[close, 1])), shape=(n, n))
    return connected_components(graph, directed=False)[1][seg].astype(np.int64)


def _join_detached_parts(
    objects: np.ndarray, areas: np.ndarray, pairs: np.ndarray, touches: np.ndarray, min_touch: int
) -> np.ndarray:
    """Objects that touch no background other than across a depth jump are parts of what they
    stand on or grow from (a head that the bush behind it outlines, above its torso): each
    joins the larger object it shares the longest boundary with, off the jumps.

    Args:
        objects: (n,) each region's object (a region index), -1 for background.
        areas: (n,) each region's pixel count.
        pairs: (M, 2) regions touching off the jumps, by ``touches`` (M,) pixel pairs; pairs
            under ``min_touch`` do not count.
    Returns:
        (n,) the objects after joining.
    """
    from hqmask.association.common import UnionFind

    object_area = np.bincount(objects[objects >= 0], areas[objects >= 0], minlength=len(objects))
    a, b = objects[pairs[:, 0]], objects[pairs[:, 1]]
    keep = (a != b) & (touches >= min_touch)
    shared: dict[int, dict[int, int]] = {}
    for x, y, t in zip(a[keep], b[keep], touches[keep]):
        for one, other in ((int(x), int(y)), (int(y), int(x))):
            shared.setdefault(one, {}).setdefault(other, 0)
            shared[one][other] += int(t)
    uf = UnionFind(len(objects))
    for label, around in shared.items():
        if label < 0 or -1 in around:
            continue
        other = max(around, key=around.get)
        if object_area[other] > object_area[label]:
            uf.union(label, other)
    return np.where(objects >= 0, uf.roots()[np.maximum(objects, 0)], -1)


@dataclass
class GraphProposer:
    """Graph segmentation with region merging; see the module docstring.

    Regions: Felzenszwalb (``scale``, ``sigma``) merged on a region adjacency graph while their
    mean CIELAB colours differ by less than ``merge_threshold``. Background: regions touching
    the border, and regions within ``background_distance`` (CIELAB) of a border region covering
    at least ``reference_fraction`` of the image. Objects: adjacent foreground regions whose hue
    differs by less than ``hue_degrees`` are joined (two-tone textures stay one object); regions
    under ``min_fraction`` of the image are dropped. With a depth map, regions are cut where
    the log depth jumps by more than ``depth_jump`` and touch only where it does not; a region
    holding near-side jump pixels for ``occluding_share`` of its outline is no background by
    colour; and an object touching no background off the jumps joins the larger object it
    shares the longest boundary with. With heights above the support plane, a region whose
    median height is at least ``standing_height`` is no background; where the plane lies
    under an orbit's focus, regions are cut where the surface rises past ``contact_height`` (an
    object of its support's colour comes apart from it), a region stands only where the view's
    SfM points back it (at least ``backed_share`` of the view's mean density of observations:
    the still room around a turntable object, which the run draws as haze, does not) and a
    region beyond the plane's reach (behind the cameras) is background (docs/masks.md).
    """

    scale: float = 100.0
    sigma: float = 0.8
    merge_threshold: float = 8.0
    background_distance: float = 8.0
    reference_fraction: float = 0.02
    hue_degrees: float = 30.0
    min_fraction: float = 0.002
    depth_jump: float = 0.2
    occluding_share: float = 0.25
    standing_height: float = 0.25
    backed_share: float = 0.2
    contact_height: float = 0.1
    cache_name = "graph"
    threadable = True

    def propose(
        self, image: np.ndarray, view: View, depth: np.ndarray | None = None, height: Heights | None = None
    ) -> Proposals:
        from skimage import color

        H, W = image.shape[:2]
        lab = color.rgb2lab(image)
        jumps = None if depth is None else depth_jumps(depth, self.depth_jump)
        seg = self._regions(image, lab, jumps, height)
        counts, mean = _region_means(seg, lab)
        background = self._background(seg, counts, mean, jumps, height)
        pairs, touches = _touching(seg, None if jumps is None else jumps.edges)
        obj = self._join(mean, background, pairs)
        if jumps is not None:
            obj = _join_detached_parts(obj, counts, pairs, touches, min_touch=max(3, int(0.01 * np.sqrt(H * W))))
        objects = obj[seg]
        labels, areas = np.unique(objects[objects >= 0], return_counts=True)
        labels = labels[areas >= self.min_fraction * H * W]
        masks = objects[None] == labels[:, None, None]
        return Proposals(masks, masks.sum((1, 2)) / (H * W))

    def _regions(
        self, image: np.ndarray, lab: np.ndarray, jumps: DepthJumps | None, height: Heights | None
    ) -> np.ndarray:
        """(H, W) region map: Felzenszwalb, merged by colour, cut at the depth ``jumps`` and,
        where the ``height`` says so, where the surface leaves the support plane."""
        from skimage import segmentation

        H, W = image.shape[:2]
        min_size = max(20, int(0.0005 * H * W))
        seg = segmentation.felzenszwalb(image, scale=self.scale, sigma=self.sigma, min_size=min_size)
        seg = merge_by_mean_colour(seg, lab, self.merge_threshold)
        if jumps is not None:
            seg = cut_at_edges(seg, jumps.edges, min_size)
        if height is not None and height.contact:
            seg = cut_at_edges(seg, _contact(height.values, self.contact_height), min_size)
        return seg

    def _background(
        self,
        seg: np.ndarray,
        counts: np.ndarray,
        mean: np.ndarray,
        jumps: DepthJumps | None,
        height: Heights | None,
    ) -> np.ndarray:
        """(n,) bool: regions touching the image border, and regions coloured like a large one
        unless the depth puts them in front of the scene; with heights above the support
        plane, no region that rises from it, and under an orbit's focus every region beyond
        the plane's reach (the cameras' ring)."""
        H, W = seg.shape
        border = np.unique(np.concatenate([seg[0], seg[-1], seg[:, 0], seg[:, -1]]))
        reference = border[counts[border] >= self.reference_fraction * H * W]
        background = np.zeros(len(counts), bool)
        background[border] = True
        if len(reference):
            alike = np.linalg.norm(mean[:, None] - mean[None, reference], axis=2).min(1) < self.background_distance
            if jumps is not None:  # what stands in front of the scene is no floor tile, whatever its colour
                alike &= ~_in_front(seg, jumps.near, self.occluding_share)
            background |= alike
        if height is not None:
            rise = _median_heights(seg, height.values)
            stands = rise >= self.standing_height
            if height.contact and height.observed is not None:  # in an orbit, only where points see it
                stands &= _backed(seg, counts, height.observed, self.backed_share)
            background &= ~stands
            if height.contact:  # in an orbit, what lies beyond the cameras is no object
                background |= np.isneginf(rise)
        return background

    def _join(self, mean: np.ndarray, background: np.ndarray, pairs: np.ndarray) -> np.ndarray:
        """(n,) each region's object (a region index; -1: background): touching foreground
        regions of similar hue joined."""
        from hqmask.association.common import UnionFind

        hue = np.degrees(np.arctan2(mean[:, 2], mean[:, 1]))
        uf = UnionFind(len(mean))
        for a, b in pairs:
            if not (background[a] or background[b]) and abs((hue[a] - hue[b] + 180) % 360 - 180) < self.hue_degrees:
                uf.union(int(a), int(b))
        obj = uf.roots()
        obj[background] = -1
        return obj
