"""SAM's automatic mask generator on the ONNX runtime.

For each crop of the crop pyramid (only the whole image by default): encode the crop once,
decode a regular grid of single-point prompts in batches, keep the masks whose predicted IoU
and stability score pass their thresholds and that are not cut off by the crop's edge, and
suppress duplicates by box NMS. Across crops, smaller crops win the NMS. Optionally, small
holes and islands are then removed and the result de-duplicated once more.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hqmask.proposers.base import Proposals
from hqmask.sam_hq.mask_ops import (
    box_nms,
    crop_boxes,
    masks_to_boxes,
    near_crop_edge,
    point_grid,
    remove_small_regions,
    stability_score,
)
from hqmask.sam_hq.model import SamHQ


@dataclass(frozen=True)
class GeneratorConfig:
    """The options of SAM's ``SamAutomaticMaskGenerator``, with its defaults."""

    points_per_side: int = 32
    points_per_batch: int = 64
    pred_iou_thresh: float = 0.88
    stability_score_thresh: float = 0.95
    stability_score_offset: float = 1.0
    box_nms_thresh: float = 0.7
    crop_n_layers: int = 0
    crop_nms_thresh: float = 0.7
    crop_overlap_ratio: float = 512 / 1500
    crop_n_points_downscale_factor: int = 1
    min_mask_region_area: int = 0


@dataclass
class GeneratedMasks:
    """The masks of one image: masks (M, H, W) bool; predicted_iou, stability (M,); boxes
    (M, 4) XYXY; points (M, 2) the prompt (x, y) of each; crop_boxes (M, 4) XYXY."""

    masks: np.ndarray
    predicted_iou: np.ndarray
    stability: np.ndarray
    boxes: np.ndarray
    points: np.ndarray
    crop_boxes: np.ndarray

    def __len__(self) -> int:
        return len(self.masks)

    def take(self, index: np.ndarray) -> GeneratedMasks:
        return GeneratedMasks(*(getattr(self, f)[index] for f in self.__dataclass_fields__))

    @staticmethod
    def concat(parts: list[GeneratedMasks], height: int, width: int) -> GeneratedMasks:
        if not parts:
            empty = np.zeros(0, np.float32)
            return GeneratedMasks(
                np.zeros((0, height, width), bool), empty, empty, *(np.zeros((0, k), np.float32) for k in (4, 2, 4))
            )
        fields = GeneratedMasks.__dataclass_fields__
        return GeneratedMasks(*(np.concatenate([getattr(p, f) for p in parts]) for f in fields))

    def proposals(self) -> Proposals:
        """As proposals scored by predicted IoU (``Proposals.paint`` paints the best on top)."""
        return Proposals(self.masks, self.predicted_iou.astype(np.float64))


class AutomaticMaskGenerator:
    """Whole-image mask proposals from a :class:`SamHQ` model; see the module docstring."""

    def __init__(self, model: SamHQ, config: GeneratorConfig = GeneratorConfig()):
        self.model = model
        self.config = config

    def generate(self, image: np.ndarray) -> GeneratedMasks:
        """All masks of ``image`` (H, W, 3) uint8 RGB."""
        cfg = self.config
        H, W = image.shape[:2]
        boxes, layers = crop_boxes(H, W, cfg.crop_n_layers, cfg.crop_overlap_ratio)
        parts = [self._crop(image, box, int(layer)) for box, layer in zip(boxes, layers)]
        out = GeneratedMasks.concat(parts, H, W)
        if len(boxes) > 1 and len(out):
            crop_area = (out.crop_boxes[:, 2] - out.crop_boxes[:, 0]) * (out.crop_boxes[:, 3] - out.crop_boxes[:, 1])
            out = out.take(box_nms(out.boxes, 1.0 / crop_area, cfg.crop_nms_thresh))
        if cfg.min_mask_region_area > 0 and len(out):
            out = self._remove_small_regions(out)
        return out

    def _crop(self, image: np.ndarray, crop_box: np.ndarray, layer: int) -> GeneratedMasks:
        cfg = self.config
        x0, y0, x1, y1 = (int(v) for v in crop_box)
        H, W = image.shape[:2]
        embedding = self.model.encode(np.ascontiguousarray(image[y0:y1, x0:x1]))
        n_side = cfg.points_per_side // cfg.crop_n_points_downscale_factor**layer
        points = point_grid(n_side) * np.array([x1 - x0, y1 - y0])
        offset = np.array([x0, y0, x0, y0], np.float32)
        crop = crop_box.astype(np.float32)
        image_box = np.array([0, 0, W, H], np.float32)
        kept = []
        for start in range(0, len(points), cfg.points_per_batch):
            batch = points[start : start + cfg.points_per_batch].astype(np.float32)
            coords = np.stack([batch, np.zeros_like(batch)], axis=1)  # each point padded with a not-a-point
            labels = np.tile(np.array([[1, -1]], np.float32), (len(batch), 1))
            pred = self.model.decode(embedding, coords, labels)
            keep = pred.iou > cfg.pred_iou_thresh
            logits, iou, batch = pred.logits[keep], pred.iou[keep], batch[keep]
            stability = stability_score(logits, self.model.info.mask_threshold, cfg.stability_score_offset)
            if cfg.stability_score_thresh > 0:
                keep = stability >= cfg.stability_score_thresh
                logits, iou, batch, stability = logits[keep], iou[keep], batch[keep], stability[keep]
            masks = logits > self.model.info.mask_threshold
            boxes = masks_to_boxes(masks) + offset
            keep = ~near_crop_edge(boxes, crop, image_box)
            n = int(keep.sum())
            if n == 0:
                continue
            full = np.zeros((n, H, W), bool)
            full[:, y0:y1, x0:x1] = masks[keep]
            kept.append(
                GeneratedMasks(
                    full, iou[keep], stability[keep], boxes[keep], batch[keep] + offset[:2], np.tile(crop, (n, 1))
                )
            )
        out = GeneratedMasks.concat(kept, H, W)
        return out.take(box_nms(out.boxes, out.predicted_iou, cfg.box_nms_thresh)) if len(out) else out

    def _remove_small_regions(self, out: GeneratedMasks) -> GeneratedMasks:
        """Fill small holes and drop small islands of every mask; changed masks get their boxes
        recomputed and lose NMS ties to unchanged ones."""
        masks = out.masks.copy()
        scores = np.ones(len(out), np.float32)
        for i, mask in enumerate(masks):
            mask, holes = remove_small_regions(mask, self.config.min_mask_region_area, "holes")
            mask, islands = remove_small_regions(mask, self.config.min_mask_region_area, "islands")
            masks[i] = mask
            scores[i] = 0.0 if holes or islands else 1.0
        out = GeneratedMasks(masks, out.predicted_iou, out.stability, masks_to_boxes(masks), out.points, out.crop_boxes)
        return out.take(box_nms(out.boxes, scores, self.config.box_nms_thresh))
