"""Image and segmentation metrics of test views."""

from __future__ import annotations

import numpy as np


def psnr(pred: np.ndarray, target: np.ndarray) -> float:
    """PSNR in dB of two uint8 images of the same shape."""
    mse = np.mean((pred.astype(np.float64) - target.astype(np.float64)) ** 2)
    return float("inf") if mse == 0 else float(10 * np.log10(255.0**2 / mse))


def object_ious(pred: np.ndarray, target: np.ndarray) -> dict[int, float]:
    """Binary IoU of every object (ID >= 1) of the (H, W) ground truth ``target`` against the
    same ID in the prediction ``pred``."""
    ious = {}
    for obj in np.unique(target):
        if obj == 0:
            continue
        p, t = pred == obj, target == obj
        ious[int(obj)] = float((p & t).sum() / (p | t).sum())
    return ious


def mean_iou(preds: list[np.ndarray], targets: list[np.ndarray]) -> float:
    """mIoU: the IoU of every (view, ground-truth object) pair, averaged."""
    values = [iou for p, t in zip(preds, targets) for iou in object_ious(p, t).values()]
    return float(np.mean(values)) if values else float("nan")
