"""The ``blobs`` family of mask errors: independent in every view, applied in this order
(sizes in pixels at 512 x 512, scaled with the image, see :mod:`dataset_tools.corruption.ops`):

1. ``coarse`` (optional): every object's mask is area-averaged down by ``coarse_factor``,
   upsampled bilinearly and re-labelled by argmax, like SAM's 256x256 low-resolution
   logits against SAM-HQ's sharp boundaries.
2. Merges: with probability ``p_merge`` an object takes the ID of its nearest neighbour.
3. Splits: with probability ``p_split`` an object is cut by a random line through its
   centroid and one side gets a new ID.
4. Missed objects: with probability ``p_miss`` an object is erased to background.
5. Boundary jitter: all boundaries move along a smooth random displacement field whose
   components have standard deviation ``jitter_px`` pixels.
6. Speckles and holes: elliptic blobs, half of them holes (background inside an object),
   half speckles (a random ID anywhere): ``small_blobs`` of 20..400 px, all under the paper's
   500 px noise-removal threshold, and a Poisson(``large_blobs``) number of 600..1500 px, over it.
7. Per-view permutation: the IDs present are renamed to random distinct IDs in 1..255.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dataset_tools.corruption.ops import area_scale, blob, coarsen, free_ids, jitter, nearest_other, objects, permute


@dataclass(frozen=True)
class BlobModel:
    """Parameters of the ``blobs`` family (see the module docstring); pixel sizes at 512 x 512."""

    jitter_px: float
    jitter_scale_px: float
    small_blobs: int
    large_blobs: float
    p_miss: float
    p_split: float
    p_merge: float
    permute: bool = True
    coarse: bool = False
    coarse_factor: int = 8


SEVERITIES: dict[str, BlobModel] = {
    "low": BlobModel(0.75, 6.0, 4, 0.0, 0.0, 0.01, 0.01),
    "medium": BlobModel(1.5, 6.0, 8, 0.3, 0.02, 0.03, 0.02),
    "high": BlobModel(3.0, 6.0, 20, 1.5, 0.06, 0.08, 0.06),
}
# Exact masks, IDs permuted per view: what association alone has to undo.
PERMUTE_ONLY = BlobModel(0.0, 6.0, 0, 0.0, 0.0, 0.0, 0.0, permute=True)
SMALL_BLOB_PX = (20.0, 400.0)  # under the paper's 500 px noise-removal threshold at 512 x 512
LARGE_BLOB_PX = (600.0, 1500.0)  # over it


def _merge(ids: np.ndarray, p: float, rng: np.random.Generator) -> np.ndarray:
    objs = objects(ids)
    if len(objs) < 2:
        return ids
    out = ids.copy()
    for label in objs[rng.uniform(size=len(objs)) < p]:
        out[out == label] = nearest_other(ids, int(label))
    return out


def _split(ids: np.ndarray, p: float, rng: np.random.Generator) -> np.ndarray:
    out = ids.copy()
    free = free_ids(ids)
    yy, xx = np.mgrid[: ids.shape[0], : ids.shape[1]]
    objs = objects(ids)
    for label in objs[rng.uniform(size=len(objs)) < p]:
        m = ids == label
        cy, cx = yy[m].mean(), xx[m].mean()
        a = rng.uniform(0, np.pi)
        side = m & ((xx - cx) * np.cos(a) + (yy - cy) * np.sin(a) > 0)
        if free and side.any():
            out[side] = free.pop()
    return out


def _speckle(ids: np.ndarray, n: int, area_range: tuple[float, float], rng: np.random.Generator) -> np.ndarray:
    out = ids.copy()
    objs = objects(ids)
    for _ in range(n):
        area = float(np.exp(rng.uniform(*np.log(area_range))))
        hole = len(objs) > 0 and rng.uniform() < 0.5
        if hole:
            ys, xs = np.nonzero(ids == rng.choice(objs))
            k = rng.integers(len(ys))
            center, value = (ys[k], xs[k]), 0
        else:
            center = (rng.integers(ids.shape[0]), rng.integers(ids.shape[1]))
            value = rng.choice(objs) if len(objs) else rng.integers(1, 256)
        out[blob(ids.shape, area, rng, center)] = value
    return out


def corrupt_mask(ids: np.ndarray, model: BlobModel, rng: np.random.Generator) -> np.ndarray:
    """Corrupt one exact ID map. (H, W) uint8 -> (H, W) uint8."""
    s = area_scale(ids.shape)
    out = coarsen(ids, model.coarse_factor) if model.coarse else ids
    out = _merge(out, model.p_merge, rng)
    out = _split(out, model.p_split, rng)
    objs = objects(out)
    for label in objs[rng.uniform(size=len(objs)) < model.p_miss]:
        out = np.where(out == label, 0, out).astype(np.uint8)
    out = jitter(out, model.jitter_px * np.sqrt(s), model.jitter_scale_px * np.sqrt(s), rng)
    out = _speckle(out, model.small_blobs, tuple(a * s for a in SMALL_BLOB_PX), rng)
    out = _speckle(out, int(rng.poisson(model.large_blobs)), tuple(a * s for a in LARGE_BLOB_PX), rng)
    return permute(out, rng) if model.permute else out
