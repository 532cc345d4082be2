"""Edits scored against their ground truth, where the scene has it (synthetic scenes with
``edit_truth/``, see :mod:`dataset_tools.synth.edit_truth`): each ground-truth object's
predicted label removed and extracted, and the renders compared with the views without it and
with it alone (:func:`eval.metrics.removal_scores`, :func:`eval.metrics.extraction_scores`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from dataset_tools.infra.errors import InputError
from dataset_tools.scene import View
from dataset_tools.synth.edit_truth import EDIT_TRUTH, read_edit_truth
from eval.lpips import LPIPS
from eval.metrics import extraction_scores, removal_scores
from gsseg.edits import apply_edit
from gsseg.fill import fill_run_removal
from gsseg.fill_options import FillOptions
from gsseg.render import Backend, get_backend, to_uint8
from gsseg.run.loaded import Run
from gsseg.segment.reassign import Segmentation
from gsseg.segment.served import complete_selection


def edit_rows(
    run: Run,
    segmentation: Segmentation,
    views: list[View],
    scene_dir: Path,
    id_map: dict[int, int],
    *,
    objects: list[int] | None = None,
    fill: FillOptions | None = None,
    lpips: LPIPS | None = None,
    backend: str | Backend = "cpu",
) -> list[dict]:
    """One row per (view, ground-truth object) that has edit truth and a predicted label:
    {view, object, label, ghost_share, removal: {...}, extraction: {...}}, and with ``fill``
    the removal filled with those options (:mod:`gsseg.fill`) too: removal_filled {...}, fill_seconds.
    ``ghost_share`` is the share of the selection's weight in the training views that the
    Gaussians left behind carry, before and after those that served it alone join it
    (:func:`gsseg.segment.served.complete_selection`, as ``gsseg edit`` records it). ``id_map``
    maps predicted labels to ground-truth IDs; ``objects`` limits the ground-truth objects
    scored; ``lpips`` adds the removals' LPIPS around the region."""
    backend = get_backend(backend)
    label_of = {gt: p for p, gt in id_map.items()}
    train = run.scene(scene_dir).split("train")
    rows = []
    with torch.no_grad():
        for obj in sorted(label_of if objects is None else objects):
            if obj not in label_of:
                continue
            completed = complete_selection(
                run.gaussians,
                segmentation.selection(label_of[obj]),
                train,
                backend=backend,
            )
            selected = completed.mask  # as gsseg edit removes and extracts
            removed = apply_edit(run.gaussians, selected, "remove")
            alone = apply_edit(run.gaussians, selected, "extract")
            filled = None
            if fill is not None:
                filled = fill_run_removal(run, selected, train, options=fill, backend=backend, progress=False)
            for view in views:
                truth = read_edit_truth(scene_dir, obj, view.stem)
                if truth is None:
                    continue
                if truth.without.shape[:2] != (view.camera.height, view.camera.width):
                    raise InputError(
                        f"{Path(scene_dir) / EDIT_TRUTH}: made at {truth.without.shape[1]}x{truth.without.shape[0]} "
                        f"but {view.name} renders at {view.camera.width}x{view.camera.height}; write it again for "
                        "the run's image folder (dataset_tools.synth.write_edit_truth(scene, images=...))."
                    )
                region = view.load_mask() == obj if view.mask_path is not None else truth.silhouette
                extracted = run.render(view, gaussians=alone, background="white", backend=backend)
                with_fill = (
                    {}
                    if filled is None
                    else {
                        "removal_filled": removal_scores(
                            run.render_rgb(view, gaussians=filled.gaussians, backend=backend),
                            truth.without,
                            region,
                            truth.seen,
                            lpips,
                        ),
                        "fill_seconds": filled.seconds,
                    }
                )
                rows.append(
                    {
                        "view": view.stem,
                        "object": obj,
                        "label": label_of[obj],
                        "ghost_share": [completed.ghost_before, completed.ghost_after],
                        "removal": removal_scores(
                            run.render_rgb(view, gaussians=removed, backend=backend),
                            truth.without,
                            region,
                            truth.seen,
                            lpips,
                        ),
                        "extraction": extraction_scores(
                            extracted.alpha.cpu().numpy(),
                            to_uint8(extracted.rgb),
                            truth.alone,
                            truth.silhouette,
                            truth.silhouette_seen,
                        ),
                        **with_fill,
                    }
                )
    return rows


def summarize_edits(rows: list[dict]) -> dict:
    """Means over the rows (PSNRs over the rows where they are finite and defined)."""

    def mean(values: list) -> float | None:
        kept = [v for v in values if v is not None and np.isfinite(v)]
        return float(np.mean(kept)) if kept else None

    scores = ("psnr", "psnr_region", "psnr_seen", "psnr_unseen", "psnr_outside", "ssim_region", "lpips_region")
    filled = [r for r in rows if "removal_filled" in r]
    return {
        **(
            {
                **{f"filled_{k}": mean([r["removal_filled"].get(k) for r in filled]) for k in scores},
                "fill_seconds": mean(list({r["object"]: r["fill_seconds"] for r in filled}.values())),  # per object
            }
            if filled
            else {}
        ),
        "pairs": len(rows),
        **{f"removal_{k}": mean([r["removal"].get(k) for r in rows]) for k in scores},
        **{
            f"ghost_share_{when}": mean(list({r["object"]: r["ghost_share"][i] for r in rows}.values()))  # per object
            for i, when in enumerate(("before", "after"))
        },
        "extraction_iou": mean([r["extraction"]["iou"] for r in rows]),
        "extraction_iou_seen": mean([r["extraction"]["iou_seen"] for r in rows]),
        "extraction_psnr_inside": mean([r["extraction"]["psnr_inside"] for r in rows]),
        "leak": mean([r["extraction"]["leak"] for r in rows]),
    }
