"""Where a view's depth jumps: the occluding contours that colour cannot see.

A dark statue head in front of a dark bush is one colour region; the depth a first 3D-GS
pass renders puts the bush twice as far. The weight-free proposer cuts its regions along
such jumps (:func:`cut_at_edges`) and never joins two regions across one, so that what
colour joins and geometry separates comes out as two objects.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy import ndimage


def log_depth(depth: np.ndarray) -> np.ndarray:
    """(H, W) float32 log camera depth of a depth map (H, W) whose 0 means "nothing opaque"
    (sky, or past the scene): such pixels take twice the farthest depth, so the outline of
    everything in front of the sky is a jump too."""
    seen = depth > 0
    far = 2.0 * float(depth[seen].max()) if seen.any() else 1.0
    return np.log(np.where(seen, depth, far)).astype(np.float32)


@dataclass(frozen=True)
class DepthJumps:
    """Where a view's depth jumps: ``edges`` (H, W) bool, the pixels on a jump; ``near`` (H, W)
    bool, those on its near side whose far side is a surface, not the sky (where something
    stands in front of the scene)."""

    edges: np.ndarray
    near: np.ndarray


def depth_jumps(depth: np.ndarray, jump: float) -> DepthJumps:
    """The jumps of a view's depth.

    A pixel is on a jump when the log depths of its 3x3 neighbourhood (after a 5x5 median,
    which removes single-pixel speckle of the render) span more than ``jump``: a jump of
    e^jump - 1 (22% at the default 0.2 of :class:`hqmask.proposers.graph.GraphProposer`) spread
    over up to 2 pixels, as the alpha-blended depth of a render smears an occluding contour.
    It is on the near side when its own log depth lies within ``jump / 2`` of the
    neighbourhood's least.

    Args:
        depth: (H, W) camera depth, 0 where nothing is opaque.
        jump: the smallest log-depth step that counts as an occlusion.
    """
    z = cv2.medianBlur(log_depth(depth), 5)
    kernel = np.ones((3, 3), np.uint8)
    low, high = cv2.erode(z, kernel), cv2.dilate(z, kernel)
    edges = (high - low) > jump
    beside_sky = cv2.dilate((depth <= 0).astype(np.uint8), kernel) > 0
    return DepthJumps(edges, edges & (z - low < jump / 2) & ~beside_sky)


def cut_at_edges(segments: np.ndarray, edges: np.ndarray, min_size: int) -> np.ndarray:
    """Split every region of a segment map into its parts that the edges separate.

    Each region's pixels off the edges fall into 4-connected parts; parts of at least
    ``min_size`` pixels become regions of their own, and every other pixel of the region
    (on an edge, or in a smaller part) joins the nearest large part of the same region. A
    region with fewer than two large parts is kept whole.

    Args:
        segments: (H, W) int region map.
        edges: (H, W) bool, :attr:`DepthJumps.edges`.
        min_size: the smallest part, in pixels, that becomes a region.
    Returns:
        (H, W) int64 region map, regions numbered from 0.
    """
    _, seg = np.unique(segments, return_inverse=True)
    seg = seg.reshape(segments.shape)
    out = np.zeros(seg.shape, np.int64)
    next_label = 0
    for region, where in enumerate(ndimage.find_objects(seg + 1)):
        inside = seg[where] == region
        parts, n = ndimage.label(inside & ~edges[where])
        sizes = np.bincount(parts.ravel(), minlength=n + 1)
        large = np.flatnonzero(sizes[1:] >= min_size) + 1
        if len(large) < 2:
            out[where][inside] = next_label
            next_label += 1
            continue
        keep = np.isin(parts, large)
        nearest = ndimage.distance_transform_edt(~keep, return_distances=False, return_indices=True)
        owner = parts[nearest[0], nearest[1]]
        renumber = np.zeros(n + 1, np.int64)
        renumber[large] = next_label + np.arange(len(large))
        out[where][inside] = renumber[owner[inside]]
        next_label += len(large)
    return out
