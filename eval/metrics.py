"""Image and segmentation metrics of test views."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import torch

from dataset_tools.label_maps import mask_box, match_ids, overlap


def psnr(pred: np.ndarray, target: np.ndarray) -> float:
    """PSNR in dB of two uint8 arrays of the same shape (images, or the pixels of a region)."""
    mse = np.mean((pred.astype(np.float64) - target.astype(np.float64)) ** 2)
    return float("inf") if mse == 0 else float(10 * np.log10(255.0**2 / mse))


def ssim_map(pred: np.ndarray, target: np.ndarray) -> np.ndarray:
    """(H, W) SSIM (kornia, 11x11 Gaussian window) of two (H, W, 3) uint8 images at each
    pixel, the mean over the channels."""
    from kornia.metrics import ssim as kornia_ssim

    def to_tensor(x: np.ndarray) -> torch.Tensor:
        return torch.from_numpy(x).permute(2, 0, 1)[None].double() / 255

    return kornia_ssim(to_tensor(pred), to_tensor(target), 11)[0].mean(0).numpy()


def ssim(pred: np.ndarray, target: np.ndarray) -> float:
    """SSIM (kornia, 11x11 Gaussian window) of two (H, W, 3) uint8 images."""
    return float(ssim_map(pred, target).mean())


def region_box(region: np.ndarray) -> tuple[slice, slice]:
    """The box around the (H, W) bool ``region`` (not empty) that LPIPS scores: widened by 8
    pixels, and to at least 64 pixels a side (the network's reach), within the image."""
    return mask_box(region, margin=8, min_side=64)


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


def similarity_alignment(source: np.ndarray, target: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """The similarity (scale s, rotation R (3, 3), translation t (3,)) that best maps the points
    ``source`` (N, 3) onto ``target`` (N, 3) in the least-squares sense (Umeyama's method):
    target ~ s R source + t."""
    mu_s, mu_t = source.mean(0), target.mean(0)
    a, b = source - mu_s, target - mu_t
    U, D, Vt = np.linalg.svd(b.T @ a / len(source))
    sign = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    R = U @ sign @ Vt
    s = float(np.trace(np.diag(D) @ sign) / (a**2).sum(1).mean())
    return s, R, mu_t - s * R @ mu_s


def camera_errors(
    estimated: list[np.ndarray], truth: list[np.ndarray], *, inlier_degrees: float = 5.0
) -> tuple[np.ndarray, np.ndarray]:
    """Per camera, the rotation error in degrees and the centre error as a share of the true
    cameras' extent (their largest distance from their mean), after a robust alignment of the
    estimated world to the true one.

    The alignment's rotation is the one that agrees with the most cameras to within
    ``inlier_degrees`` (each camera's own alignment tried in turn), refined as the chordal mean
    over those cameras; the centres are aligned by the similarity that best maps those
    cameras' centres (:func:`similarity_alignment`). A few cameras posed wrongly (in either
    model: a capture of a symmetric or repetitive scene can put some on the far side) then
    show their own error without moving the frame in which the others are scored, as in
    COLMAP's RANSAC model aligner. The orientations, not the centres, fix the rotation:
    centres along an arc fix it badly.

    Args:
        estimated, truth: per camera, (3, 4) world-to-camera [R | t], in the same order.
    Returns:
        (rotation errors (N,), centre errors (N,)).
    """
    est_R = np.stack([p[:, :3] for p in estimated])
    true_R = np.stack([p[:, :3] for p in truth])

    def errors(align: np.ndarray) -> np.ndarray:  # align: estimated world -> true world
        cos = (np.einsum("nij,kj,nik->n", est_R, align, true_R) - 1) / 2  # trace(e align^T g^T)
        return np.degrees(np.arccos(np.clip(cos, -1, 1)))

    candidates = [g.T @ e for e, g in zip(est_R, true_R)]  # the alignment that makes camera i exact
    agree = max((errors(a) < inlier_degrees for a in candidates), key=np.count_nonzero)
    U, _, Vt = np.linalg.svd(np.einsum("nji,njk->ik", true_R[agree], est_R[agree]))
    align = U @ np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))]) @ Vt

    def centers(poses: list[np.ndarray]) -> np.ndarray:
        return np.stack([-p[:, :3].T @ p[:, 3] for p in poses])

    est, true = centers(estimated), centers(truth)
    s, R, t = similarity_alignment(est[agree], true[agree])
    extent = float(np.linalg.norm(true - true.mean(0), axis=1).max())
    return errors(align), np.linalg.norm((s * est @ R.T + t) - true, axis=1) / extent


def removal_scores(
    removed: np.ndarray,
    truth: np.ndarray,
    region: np.ndarray,
    seen: np.ndarray,
    lpips: Callable[[np.ndarray, np.ndarray], float] | None = None,
) -> dict[str, float | None]:
    """A removal against the view rendered without the object: PSNR and SSIM of the whole view,
    PSNR over the ``region`` (H, W) bool the object covered (where a ghost of it would show),
    over its ``seen`` part (whose background some training view saw), its unseen part (what
    a fill must invent) and outside it (what a removal must leave as it was); SSIM over the
    region (the mean of the SSIM map there), and with an ``lpips`` network
    (:class:`eval.lpips.LPIPS`) its distance over the box around the region (:func:`region_box`).

    Args:
        removed, truth: (H, W, 3) uint8.
    """

    def masked_psnr(mask: np.ndarray) -> float | None:
        return psnr(removed[mask], truth[mask]) if mask.any() else None

    similarity = ssim_map(removed, truth)
    scores = {
        "psnr": psnr(removed, truth),
        "ssim": float(similarity.mean()),
        "psnr_region": masked_psnr(region),
        "psnr_seen": masked_psnr(region & seen),
        "psnr_unseen": masked_psnr(region & ~seen),
        "psnr_outside": masked_psnr(~region),
        "ssim_region": float(similarity[region].mean()) if region.any() else None,
    }
    if lpips is not None:
        box = region_box(region) if region.any() else None
        scores["lpips_region"] = lpips(removed[box], truth[box]) if box is not None else None
    return scores


def extraction_scores(
    alpha: np.ndarray,
    rgb: np.ndarray,
    truth: np.ndarray,
    silhouette: np.ndarray,
    seen: np.ndarray | None = None,
    margin: int = 2,
) -> dict[str, float]:
    """An extraction against the object rendered alone: IoU of its alpha >= 0.5 silhouette
    with the true silhouette, PSNR inside the true silhouette of the render on white, and the
    leak: the share of the extraction's opacity outside the true silhouette dilated by
    ``margin`` pixels (floor, shadow or neighbours carried along). With ``seen``, also the IoU
    over the pixels outside the silhouette's never-seen part (what no training view showed
    counts neither way): ``iou_seen``.

    Args:
        alpha: (H, W) float accumulated opacity. rgb, truth: (H, W, 3) uint8 on white.
        silhouette: (H, W) bool. seen: (H, W) bool, the silhouette pixels a training view saw.
    """
    import cv2

    iou, _ = binary_scores(alpha >= 0.5, silhouette)
    grown = cv2.dilate(silhouette.astype(np.uint8), np.ones((2 * margin + 1, 2 * margin + 1), np.uint8)) > 0
    total = float(alpha.sum())
    out = {
        "iou": iou,
        "psnr_inside": psnr(rgb[silhouette], truth[silhouette]) if silhouette.any() else None,
        "leak": float(alpha[~grown].sum() / total) if total > 0 else 0.0,
    }
    if seen is not None:
        scored = ~(silhouette & ~seen)
        out["iou_seen"] = binary_scores((alpha >= 0.5) & scored, silhouette & scored)[0]
    return out
