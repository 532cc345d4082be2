"""Operations both corruption families are built from. Sizes are given at a reference image
of 512 x 512 pixels and scale with the image: a proposer's errors are a share of what it
sees (SAM-HQ works on a 1024-pixel frame whatever the photo's size), not a fixed count of
pixels."""

from __future__ import annotations

import cv2
import numpy as np
from scipy import ndimage

REFERENCE_AREA = 512 * 512


def area_scale(shape: tuple[int, ...]) -> float:
    """Image area over the reference 512 x 512: multiplies areas; its square root, lengths."""
    return shape[0] * shape[1] / REFERENCE_AREA


def objects(ids: np.ndarray) -> np.ndarray:
    """The object IDs (> 0) present in an (H, W) map, sorted."""
    present = np.unique(ids)
    return present[present > 0]


def free_ids(ids: np.ndarray) -> list[int]:
    """IDs 255, 254, ... not present in ``ids``: pop() gives the smallest free one last."""
    used = set(objects(ids).tolist())
    return [label for label in range(255, 0, -1) if label not in used]


def coarsen(ids: np.ndarray, factor: int) -> np.ndarray:
    """Boundaries computed at 1/``factor`` resolution and upsampled. (H, W) uint8 -> (H, W) uint8."""
    H, W = ids.shape
    labels = np.unique(ids)
    small = (max(1, W // factor), max(1, H // factor))
    scores = np.stack(
        [
            cv2.resize(
                cv2.resize((ids == label).astype(np.float32), small, interpolation=cv2.INTER_AREA),
                (W, H),
                interpolation=cv2.INTER_LINEAR,
            )
            for label in labels
        ]
    )
    return labels[np.argmax(scores, axis=0)].astype(np.uint8)


def jitter(ids: np.ndarray, amplitude: float, scale: float, rng: np.random.Generator) -> np.ndarray:
    """Every boundary moved along a smooth random displacement field whose components have
    standard deviation ``amplitude`` pixels and correlation length ``scale`` pixels."""
    if amplitude <= 0:
        return ids
    H, W = ids.shape
    flow = []
    for _ in range(2):
        f = ndimage.gaussian_filter(rng.normal(size=(H, W)), scale)
        flow.append(f / (f.std() + 1e-12) * amplitude)
    gx, gy = np.meshgrid(np.arange(W, dtype=np.float32), np.arange(H, dtype=np.float32))
    return cv2.remap(
        ids,
        gx + flow[0].astype(np.float32),
        gy + flow[1].astype(np.float32),
        cv2.INTER_NEAREST,
        borderMode=cv2.BORDER_REPLICATE,
    )


def ellipse(shape: tuple[int, int], center: tuple[float, float], axes: tuple[float, float], angle: float) -> np.ndarray:
    """(H, W) bool filled ellipse; ``center`` (row, col), ``axes`` semi-axes in pixels, ``angle`` in degrees."""
    mask = np.zeros(shape, np.uint8)
    cv2.ellipse(
        mask,
        (int(center[1]), int(center[0])),
        (max(1, int(round(axes[0]))), max(1, int(round(axes[1])))),
        float(angle),
        0,
        360,
        1,
        -1,
    )
    return mask.astype(bool)


def blob(shape: tuple[int, int], area: float, rng: np.random.Generator, center: tuple[int, int]) -> np.ndarray:
    """(H, W) bool ellipse of about ``area`` pixels at ``center`` (row, col), random aspect and angle."""
    ratio = rng.uniform(0.4, 1.0)
    a = np.sqrt(area / (np.pi * ratio))
    return ellipse(shape, center, (a, a * ratio), rng.uniform(0, 180))


def permute(ids: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """The IDs present renamed to random distinct IDs in 1..255."""
    objs = objects(ids)
    lut = np.arange(256, dtype=np.uint8)
    lut[objs] = rng.choice(np.arange(1, 256), size=len(objs), replace=False)
    return lut[ids]


def nearest_other(ids: np.ndarray, label: int) -> int | None:
    """The object of ``ids`` nearest to ``label``'s pixels (None when it is alone)."""
    others = [o for o in objects(ids) if o != label]
    if not others:
        return None
    dist = ndimage.distance_transform_edt(ids != label)
    return int(min(others, key=lambda o: dist[ids == o].min()))
