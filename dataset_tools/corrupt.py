"""Realistic imperfect masks from exact ones, at three severities, deterministic by seed.

The corruption model, applied to each view independently, in this order:

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
   half speckles (a random ID anywhere): ``small_blobs`` of 20..400 px, all under the 500 px
   noise-removal threshold, and a Poisson(``large_blobs``) number of 600..1500 px, over it.
7. Per-view permutation: the IDs present are renamed to random distinct IDs in 1..255.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Literal

import cv2
import numpy as np
from scipy import ndimage
from tqdm import tqdm

from dataset_tools.atomic import atomic_directory, write_bytes_atomic
from dataset_tools.errors import InputError
from dataset_tools.image_files import encode_png
from dataset_tools.label_maps import matched_error
from dataset_tools.scene import load_scene

Severity = Literal["low", "medium", "high"]


@dataclass(frozen=True)
class CorruptionModel:
    """Parameters of the corruption model (see the module docstring)."""

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


SEVERITIES: dict[str, CorruptionModel] = {
    "low": CorruptionModel(0.75, 6.0, 4, 0.0, 0.0, 0.01, 0.01),
    "medium": CorruptionModel(1.5, 6.0, 8, 0.3, 0.02, 0.03, 0.02),
    "high": CorruptionModel(3.0, 6.0, 20, 1.5, 0.06, 0.08, 0.06),
}
# Exact masks, IDs permuted per view: what association alone has to undo.
PERMUTE_ONLY = CorruptionModel(0.0, 6.0, 0, 0.0, 0.0, 0.0, 0.0, permute=True)


def corruption_model(severity: str, *, coarse: bool = False) -> CorruptionModel:
    if severity not in SEVERITIES:
        raise InputError(f"--severity {severity}: use low, medium or high.")
    model = SEVERITIES[severity]
    return CorruptionModel(**{**asdict(model), "coarse": coarse})


def coarsen(ids: np.ndarray, factor: int) -> np.ndarray:
    """Boundaries computed at 1/``factor`` resolution and upsampled. (H, W) uint8 -> (H, W) uint8."""
    H, W = ids.shape
    labels = np.unique(ids)
    small = (max(1, W // factor), max(1, H // factor))
    scores = np.stack(
        [cv2.resize(cv2.resize((ids == l).astype(np.float32), small, interpolation=cv2.INTER_AREA), (W, H),
                    interpolation=cv2.INTER_LINEAR) for l in labels]
    )
    return labels[np.argmax(scores, axis=0)].astype(np.uint8)


def _objects(ids: np.ndarray) -> np.ndarray:
    present = np.unique(ids)
    return present[present > 0]


def _merge(ids: np.ndarray, p: float, rng: np.random.Generator) -> np.ndarray:
    objs = _objects(ids)
    if len(objs) < 2:
        return ids
    out = ids.copy()
    for l in objs[rng.uniform(size=len(objs)) < p]:
        dist = ndimage.distance_transform_edt(ids != l)
        others = [o for o in objs if o != l]
        nearest = min(others, key=lambda o: dist[ids == o].min())
        out[out == l] = nearest
    return out


def _split(ids: np.ndarray, p: float, rng: np.random.Generator) -> np.ndarray:
    out = ids.copy()
    free = [l for l in range(255, 0, -1) if l not in set(_objects(ids).tolist())]
    yy, xx = np.mgrid[: ids.shape[0], : ids.shape[1]]
    for l in _objects(ids)[rng.uniform(size=len(_objects(ids))) < p]:
        m = ids == l
        cy, cx = yy[m].mean(), xx[m].mean()
        a = rng.uniform(0, np.pi)
        side = m & ((xx - cx) * np.cos(a) + (yy - cy) * np.sin(a) > 0)
        if free and side.any():
            out[side] = free.pop()
    return out


def _jitter(ids: np.ndarray, amplitude: float, scale: float, rng: np.random.Generator) -> np.ndarray:
    if amplitude <= 0:
        return ids
    H, W = ids.shape
    flow = []
    for _ in range(2):
        f = ndimage.gaussian_filter(rng.normal(size=(H, W)), scale)
        flow.append(f / (f.std() + 1e-12) * amplitude)
    gx, gy = np.meshgrid(np.arange(W, dtype=np.float32), np.arange(H, dtype=np.float32))
    return cv2.remap(ids, gx + flow[0].astype(np.float32), gy + flow[1].astype(np.float32), cv2.INTER_NEAREST,
                     borderMode=cv2.BORDER_REPLICATE)


def _blob(shape: tuple[int, int], area: float, rng: np.random.Generator, center: tuple[int, int]) -> np.ndarray:
    ratio = rng.uniform(0.4, 1.0)
    a = np.sqrt(area / (np.pi * ratio))
    mask = np.zeros(shape, np.uint8)
    axes = (max(1, int(round(a))), max(1, int(round(a * ratio))))
    cv2.ellipse(mask, (int(center[1]), int(center[0])), axes, float(rng.uniform(0, 180)), 0, 360, 1, -1)
    return mask.astype(bool)


def _speckle(ids: np.ndarray, n: int, area_range: tuple[float, float], rng: np.random.Generator) -> np.ndarray:
    out = ids.copy()
    objs = _objects(ids)
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
        out[_blob(ids.shape, area, rng, center)] = value
    return out


def _permute(ids: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    objs = _objects(ids)
    lut = np.arange(256, dtype=np.uint8)
    lut[objs] = rng.choice(np.arange(1, 256), size=len(objs), replace=False)
    return lut[ids]


def corrupt_mask(ids: np.ndarray, model: CorruptionModel, rng: np.random.Generator) -> np.ndarray:
    """Corrupt one exact ID map. (H, W) uint8 -> (H, W) uint8."""
    out = coarsen(ids, model.coarse_factor) if model.coarse else ids
    out = _merge(out, model.p_merge, rng)
    out = _split(out, model.p_split, rng)
    objs = _objects(out)
    for l in objs[rng.uniform(size=len(objs)) < model.p_miss]:
        out = np.where(out == l, 0, out).astype(np.uint8)
    out = _jitter(out, model.jitter_px, model.jitter_scale_px, rng)
    out = _speckle(out, model.small_blobs, (20.0, 400.0), rng)
    out = _speckle(out, int(rng.poisson(model.large_blobs)), (600.0, 1500.0), rng)
    return _permute(out, rng) if model.permute else out


def corrupt_scene(
    scene_dir: Path | str,
    out_masks: str,
    severity: str = "medium",
    *,
    coarse: bool = False,
    seed: int = 0,
    masks: str = "object_mask",
    overwrite: bool = False,
    progress: bool = True,
) -> dict:
    """Write corrupted copies of a scene's exact masks to ``scene_dir/out_masks/*.png``.

    Also writes ``corruption.json`` there (the model and the measured error of every view)
    and returns it. The measured error is the fraction of pixels that disagree with the exact
    mask after the best renaming of IDs (see ``label_maps.matched_error``).
    """
    scene_dir = Path(scene_dir)
    model = corruption_model(severity, coarse=coarse)
    if out_masks == masks:
        raise InputError(f"--out-masks {out_masks}: would overwrite the exact masks; choose another name.")
    scene = load_scene(scene_dir, masks=masks)
    if scene.mask_dir is None:
        raise InputError(f"{scene_dir / masks}: no masks to corrupt; generate the scene with `python -m dataset_tools synth`.")
    target = scene_dir / out_masks
    if target.exists() and not overwrite:
        raise InputError(f"{target}: already exists; choose another --out-masks or pass --force.")
    errors = {}
    with atomic_directory(target, overwrite=overwrite) as tmp:
        for k, view in enumerate(tqdm(scene.views, desc=f"corrupting ({severity})", disable=not progress)):
            gt = view.load_mask()
            if gt is None:
                continue
            rng = np.random.default_rng([seed, k])
            noisy = corrupt_mask(gt, model, rng)
            write_bytes_atomic(tmp / f"{view.stem}.png", encode_png(noisy))
            errors[view.stem] = matched_error(noisy, gt)
        report = {
            "severity": severity,
            "seed": seed,
            "model": asdict(model),
            "mean_error": float(np.mean(list(errors.values()))),
            "error_per_view": errors,
        }
        write_bytes_atomic(tmp / "corruption.json", json.dumps(report, indent=2, sort_keys=True).encode())
    return report
