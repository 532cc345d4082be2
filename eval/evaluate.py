"""Scores of a segmented run on a scene's test views, in the two protocols of the paper.

- ``visible`` (occlusion-aware): the whole scene is rendered and each pixel takes the label
  whose Gaussians carry the largest blended weight.
- ``extracted`` (the paper's): each object's Gaussians are rendered alone and thresholded
  (alpha >= 0.5, which is what thresholding a render on white measures, free of the object's
  colour).

Predicted labels are renamed to ground-truth IDs by one Hungarian matching on the pixel
overlap of the visible label maps over all test views. Per (view, ground-truth object):
binary IoU and pixel accuracy; mIoU and mAcc average them. PSNR and SSIM per test view.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
from tqdm import tqdm

from dataset_tools.infra.atomic import write_bytes_atomic
from dataset_tools.infra.errors import InputError, OptionError
from dataset_tools.label_maps import match_ids, overlap
from dataset_tools.scene import View, mask_folder
from eval.edit_scores import summarize_edits
from eval.lpips import LPIPS
from eval.metrics import binary_scores, psnr, ssim
from eval.renders import ViewRenders, render_view
from gsseg.render import Backend
from gsseg.run.loaded import Run, load_run
from gsseg.segment.reassign import Segmentation

PROTOCOLS = ("visible", "extracted")
LPIPS_NA = "n/a: weights not available"


@dataclass
class Evaluation:
    """Every score of one run on one scene; ``summary()`` has the per-scene averages.

    objects: rows {view, object, protocol, iou, acc}; views: rows {view, psnr, ssim} (and lpips
    when an LPIPS network was given); id_map: predicted label -> ground-truth ID (unmatched
    labels are absent); edits: rows of :func:`eval.edit_scores.edit_rows` where the scene has
    edit truth.
    """

    run: str
    scene: str
    split: str
    id_map: dict[int, int] = field(default_factory=dict)
    objects: list[dict] = field(default_factory=list)
    views: list[dict] = field(default_factory=list)
    edits: list[dict] = field(default_factory=list)

    def summary(self) -> dict:
        lpips = [v["lpips"] for v in self.views if "lpips" in v]
        out: dict = {
            "views": len(self.views),
            "psnr": _mean([v["psnr"] for v in self.views]),
            "ssim": _mean([v["ssim"] for v in self.views]),
            "lpips": _mean(lpips) if lpips and len(lpips) == len(self.views) else LPIPS_NA,
        }
        for protocol in PROTOCOLS:
            rows = [r for r in self.objects if r["protocol"] == protocol]
            out[protocol] = {
                "miou": _mean([r["iou"] for r in rows]),
                "macc": _mean([r["acc"] for r in rows]),
                "pairs": len(rows),
            }
        if self.edits:
            out["edits"] = summarize_edits(self.edits)
        return out

    def per_object(self) -> dict[int, dict[str, float]]:
        """Per ground-truth object, its IoU and accuracy in each protocol averaged over views."""
        out: dict[int, dict[str, float]] = {}
        for obj in sorted({r["object"] for r in self.objects}):
            for protocol in PROTOCOLS:
                rows = [r for r in self.objects if r["object"] == obj and r["protocol"] == protocol]
                out.setdefault(obj, {})[f"{protocol}_iou"] = _mean([r["iou"] for r in rows])
                out[obj][f"{protocol}_acc"] = _mean([r["acc"] for r in rows])
        return out

    def to_json(self) -> dict:
        return {"summary": self.summary(), **asdict(self)}

    @classmethod
    def from_json(cls, data: dict) -> Evaluation:
        fields = {k: v for k, v in data.items() if k in {f.name for f in dataclasses.fields(cls)}}
        fields["id_map"] = {int(k): v for k, v in fields.get("id_map", {}).items()}
        return cls(**fields)

    def save(self, path: Path) -> None:
        """Write the scores as JSON (a report's ``metrics.json``; a run's copy is written by
        :meth:`gsseg.run.folder.RunFolder.write_evaluation`)."""
        write_bytes_atomic(path, (json.dumps(self.to_json(), indent=2) + "\n").encode())


def _mean(values: list[float]) -> float | None:
    return float(np.mean(values)) if values else None


def score_views(
    renders: list[ViewRenders], *, run: str, scene: str, split: str, lpips: LPIPS | None = None
) -> Evaluation:
    """Match predicted labels to ground-truth IDs and score every view in both protocols
    (and by ``lpips`` when given)."""
    with_truth = [r for r in renders if r.truth is not None]
    mapping = match_ids(sum(overlap(r.visible, r.truth) for r in with_truth)) if with_truth else np.full(256, -1)
    id_map = {int(p): int(g) for p, g in enumerate(mapping) if p > 0 and g > 0}
    label_of = {g: p for p, g in id_map.items()}
    result = Evaluation(run=run, scene=scene, split=split, id_map=id_map)
    for r in renders:
        result.views.append(
            {
                "view": r.stem,
                "psnr": psnr(r.rgb, r.image),
                "ssim": ssim(r.rgb, r.image),
                **({"lpips": lpips(r.rgb, r.image)} if lpips is not None else {}),
            }
        )
        if r.truth is None:
            continue
        renamed = mapping[r.visible]
        for obj in (int(o) for o in np.unique(r.truth) if o > 0):
            target = r.truth == obj
            label = label_of.get(obj)
            extracted = r.extracted.get(label, np.zeros_like(target)) if label is not None else np.zeros_like(target)
            for protocol, pred in (("visible", renamed == obj), ("extracted", extracted)):
                iou, acc = binary_scores(pred, target)
                result.objects.append({"view": r.stem, "object": obj, "protocol": protocol, "iou": iou, "acc": acc})
    return result


def load_inputs(
    run_dir: Path, scene_dir: Path, gt_masks: str | None, split: str, other_scene: bool = False
) -> tuple[Run, Segmentation, list[View]]:
    """The run, its labels and the scene's ``split`` views, refusing what cannot be evaluated
    (a scene other than the run's unless ``other_scene``)."""
    run = load_run(run_dir, other_scene=other_scene)
    segmentation = run.labels()
    if gt_masks is not None and not (scene_dir / mask_folder(scene_dir, gt_masks)).is_dir():
        raise OptionError(
            "no ground-truth masks for the metrics; pass the scene's ground-truth mask folder as {gt_masks}.",
            file=scene_dir / gt_masks,
        )
    views = run.scene(scene_dir, masks=gt_masks).split(split)
    if not views:
        raise InputError(f"{scene_dir}: the scene has no {split} views to evaluate.")
    return run, segmentation, views


def evaluate(
    run: Run,
    segmentation: Segmentation,
    views: list[View],
    *,
    with_truth: bool,
    scene: str,
    split: str,
    backend: str | Backend,
    lpips: LPIPS | None = None,
    progress: bool = True,
) -> tuple[Evaluation, list[ViewRenders]]:
    """Render ``views`` with the segmented run and score them (against their masks when
    ``with_truth``; by ``lpips`` when given). Returns the scores and the renders."""
    renders = [
        render_view(run, segmentation, v, backend=backend, truth=v.load_mask() if with_truth else None)
        for v in tqdm(views, desc="evaluating", unit="view", disable=not progress)
    ]
    return score_views(renders, run=str(run.root), scene=scene, split=split, lpips=lpips), renders
