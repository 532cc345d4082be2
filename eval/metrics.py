"""Image and segmentation metrics of test views."""

from __future__ import annotations

import numpy as np
import torch

from dataset_tools.label_maps import match_ids, overlap


def psnr(pred: np.ndarray, target: np.ndarray) -> float:
    """PSNR in dB of two uint8 images of the same shape."""
    mse = np.mean((pred.astype(np.float64) - target.astype(np.float64)) ** 2)
    return float("inf") if mse == 0 else float(10 * np.log10(255.0**2 / mse))


def ssim(pred: np.ndarray, target: np.ndarray) -> float:
    """SSIM (kornia, 11x11 Gaussian window) of two (H, W, 3) uint8 images."""
    from kornia.metrics import ssim as kornia_ssim

    def to_tensor(x: np.ndarray) -> torch.Tensor:
        return torch.from_numpy(x).permute(2, 0, 1)[None].double() / 255

    return float(kornia_ssim(to_tensor(pred), to_tensor(target), 11).mean())


def binary_scores(pred: np.ndarray, target: np.ndarray) -> tuple[float, float]:
    """IoU and pixel accuracy of a binary mask ``pred`` against ``target``, both (H, W) bool.

    An object absent from both has IoU 1."""
    union = np.count_nonzero(pred | target)
    iou = np.count_nonzero(pred & target) / union if union else 1.0
    return float(iou), float(np.mean(pred == target))


def object_ious(pred: np.ndarray, target: np.ndarray) -> dict[int, float]:
    """Binary IoU of every object (ID >= 1) of the (H, W) ground truth ``target`` against the
    same ID in the prediction ``pred``."""
    return {int(obj): binary_scores(pred == obj, target == obj)[0] for obj in np.unique(target) if obj != 0}


def mean_iou(preds: list[np.ndarray], targets: list[np.ndarray]) -> float:
    """mIoU: the IoU of every (view, ground-truth object) pair, averaged."""
    values = [iou for p, t in zip(preds, targets) for iou in object_ious(p, t).values()]
    return float(np.mean(values)) if values else float("nan")


def matched_miou(preds: list[np.ndarray], targets: list[np.ndarray]) -> float:
    """mIoU after renaming predicted IDs to ground-truth IDs by one Hungarian matching on the
    pixel overlap summed over all views (unmatched predicted IDs count as wrong everywhere)."""
    mapping = match_ids(sum(overlap(p, t) for p, t in zip(preds, targets)))
    return mean_iou([np.where(mapping[p] >= 0, mapping[p], 255).astype(np.uint8) for p in preds], targets)


def segment_ceiling(preds: list[np.ndarray], gts: list[np.ndarray]) -> float:
    """The best ID consistency any choice of IDs for the segments of ``preds`` can reach: the
    share of ground-truth object pixels that carry their ID when every predicted segment (an
    ID > 0 of one view) takes the ground-truth ID it overlaps most; background stays."""
    hit = total = 0
    for p, g in zip(preds, gts):
        best = overlap(p, g).argmax(1)
        best[0] = 0
        obj = g > 0
        hit += int(np.count_nonzero(best[p[obj]] == g[obj]))
        total += int(np.count_nonzero(obj))
    return hit / max(total, 1)
