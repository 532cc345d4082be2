"""Mask proposers: one image in, candidate object masks with scores out.

- ``graph``: weight-free default. Felzenszwalb's graph segmentation, regions merged by mean
  colour on a region adjacency graph (scikit-image), and background removed: regions that
  touch the image border, and regions whose colour is close to a large border region (a
  tiled floor whose inner tiles do not reach the border), are background. Adjacent
  foreground regions of similar hue are joined into one object.
- ``existing``: masks already on disk (e.g. a corrupted folder), one proposal per ID.
- ``sam-hq``: SAM-HQ's automatic mask generator through ONNX Runtime (``--model DIR``).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dataset_tools.errors import InputError
from dataset_tools.scene import View
from hqmask.proposals import Proposals, Proposer


def _from_label_map(ids: np.ndarray) -> Proposals:
    labels = np.unique(ids)
    labels = labels[labels > 0]
    return Proposals(ids[None] == labels[:, None, None], np.ones(len(labels)))


class ExistingMasks:
    """Proposals read from a mask folder of the scene: one proposal per ID of the view's map."""

    cache_name = None

    def propose(self, image: np.ndarray, view: View) -> Proposals:
        ids = view.load_mask()
        if ids is None:
            return Proposals(np.zeros((0, *image.shape[:2]), bool), np.zeros(0))
        return _from_label_map(ids)


def _adjacent_pairs(seg: np.ndarray) -> np.ndarray:
    """Unique pairs (a < b) of region labels that touch (4-neighbourhood). Returns (M, 2)."""
    pairs = [np.stack([seg[:, :-1].ravel(), seg[:, 1:].ravel()], 1), np.stack([seg[:-1].ravel(), seg[1:].ravel()], 1)]
    p = np.concatenate(pairs)
    p = np.sort(p[p[:, 0] != p[:, 1]], axis=1)
    return np.unique(p, axis=0)


@dataclass
class GraphProposer:
    """Graph segmentation with region merging; see the module docstring.

    Regions: Felzenszwalb (``scale``, ``sigma``) merged on a region adjacency graph while their
    mean CIELAB colours differ by less than ``merge_threshold``. Background: regions touching
    the border, and regions within ``background_distance`` (CIELAB) of a border region covering
    at least ``reference_fraction`` of the image. Objects: adjacent foreground regions whose hue
    differs by less than ``hue_degrees`` are joined (two-tone textures stay one object); regions
    under ``min_fraction`` of the image are dropped.
    """

    scale: float = 100.0
    sigma: float = 0.8
    merge_threshold: float = 8.0
    background_distance: float = 8.0
    reference_fraction: float = 0.02
    hue_degrees: float = 30.0
    min_fraction: float = 0.002
    cache_name = "graph"

    def propose(self, image: np.ndarray, view: View) -> Proposals:
        from skimage import color, graph, segmentation

        from hqmask.association.common import UnionFind

        H, W = image.shape[:2]
        lab = color.rgb2lab(image)
        seg = segmentation.felzenszwalb(image, scale=self.scale, sigma=self.sigma, min_size=max(20, int(0.0005 * H * W)))
        seg = graph.cut_threshold(seg, graph.rag_mean_color(lab, seg), self.merge_threshold)
        n = int(seg.max()) + 1
        counts = np.bincount(seg.ravel(), minlength=n).astype(float)
        mean = np.stack([np.bincount(seg.ravel(), lab[..., c].ravel(), n) for c in range(3)], 1) / np.maximum(counts, 1)[:, None]
        border = np.unique(np.concatenate([seg[0], seg[-1], seg[:, 0], seg[:, -1]]))
        reference = border[counts[border] >= self.reference_fraction * H * W]
        background = np.zeros(n, bool)
        background[border] = True
        if len(reference):
            background |= np.linalg.norm(mean[:, None] - mean[None, reference], axis=2).min(1) < self.background_distance
        hue = np.degrees(np.arctan2(mean[:, 2], mean[:, 1]))
        uf = UnionFind(n)
        for a, b in _adjacent_pairs(seg):
            if not (background[a] or background[b]) and abs((hue[a] - hue[b] + 180) % 360 - 180) < self.hue_degrees:
                uf.union(int(a), int(b))
        obj = uf.roots()
        obj[background] = -1
        objects = obj[seg]
        labels, areas = np.unique(objects[objects >= 0], return_counts=True)
        labels = labels[areas >= self.min_fraction * H * W]
        masks = objects[None] == labels[:, None, None]
        return Proposals(masks, masks.sum((1, 2)) / (H * W))


class SamHQProposer:
    """SAM-HQ's automatic mask generator (ONNX Runtime); proposals scored by predicted IoU."""

    def __init__(self, generator):
        """``generator``: a :class:`hqmask.sam_hq.AutomaticMaskGenerator`."""
        self.generator = generator
        points = generator.config.points_per_side
        self.cache_name = f"sam-hq-{generator.model.fingerprint}-p{points}"

    def propose(self, image: np.ndarray, view: View) -> Proposals:
        return self.generator.generate(image).proposals()


def make_proposer(
    name: str,
    model_dir: str | None = None,
    *,
    device: str = "auto",
    threads: int = 0,
    points_per_side: int = 32,
    embedding_cache: Path | None = None,
) -> Proposer:
    """The proposer called ``name``: ``graph``, ``existing`` or ``sam-hq``.

    The keyword options configure ``sam-hq``: ONNX Runtime device and threads, the point grid
    of the automatic generator, and a folder to cache image embeddings in.
    """
    if name == "graph":
        return GraphProposer()
    if name == "existing":
        return ExistingMasks()
    if name == "sam-hq":
        from hqmask.sam_hq import EXPORT_HINT, AutomaticMaskGenerator, GeneratorConfig, SamHQ

        if not model_dir:
            raise InputError(f"--proposer sam-hq needs --model DIR, a SAM-HQ ONNX model folder; {EXPORT_HINT}.")
        model = SamHQ(model_dir, device=device, threads=threads, cache_dir=embedding_cache)
        return SamHQProposer(AutomaticMaskGenerator(model, GeneratorConfig(points_per_side=points_per_side)))
    raise InputError(f"--proposer {name}: unknown proposer; use graph, sam-hq or existing.")
