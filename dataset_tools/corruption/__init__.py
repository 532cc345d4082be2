"""Realistic imperfect masks from exact ones, deterministic by seed, in two independent
families of errors at three severities each:

- ``blobs`` (:mod:`dataset_tools.corruption.blobs`): errors drawn independently in every
  view: merges, splits, misses, boundary jitter, speckles, holes and large wrong blobs;
- ``proposer`` (:mod:`dataset_tools.corruption.proposer`): what an automatic proposer does
  over a capture, errors persisting over runs of consecutive views: objects given as parts,
  merged with a neighbour or missed for a run of views, shadows and background patches
  proposed as objects, boundaries bleeding into the background.

Both permute the IDs of every view. A method tuned on one family is checked on the other.
"""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path

import numpy as np
from tqdm import tqdm

from dataset_tools.corruption import blobs, proposer
from dataset_tools.corruption.blobs import PERMUTE_ONLY, BlobModel, corrupt_mask
from dataset_tools.corruption.ops import coarsen
from dataset_tools.image_files import encode_png
from dataset_tools.infra.atomic import atomic_directory, write_bytes_atomic
from dataset_tools.infra.errors import InputError, OptionError, OutputExists, check_seed
from dataset_tools.infra.locks import exclusive_folder
from dataset_tools.infra.names import plain_name
from dataset_tools.infra.overlap import refuse_overlap, scene_inputs
from dataset_tools.label_maps import matched_error
from dataset_tools.mask_manifest import MANIFEST, manifest_bytes, refuse_truth
from dataset_tools.scene import GT_MASKS, load_scene, mask_folder

FAMILIES = ("blobs", "proposer")
RUNS_STREAM = 2**31  # the seed stream of the proposer family's runs, apart from every view's
SEVERITY_NAMES = ("low", "medium", "high")
SEVERITY = "medium"  # the default

__all__ = ["FAMILIES", "PERMUTE_ONLY", "SEVERITY_NAMES", "BlobModel", "coarsen", "corrupt_mask", "corrupt_scene"]


def _check(family: str, severity: str, coarse: bool) -> None:
    if family not in FAMILIES:
        raise OptionError(f"{{model}}: use {' or '.join(FAMILIES)}.", model=family)
    if severity not in SEVERITY_NAMES:
        raise OptionError("{severity}: use low, medium or high.", severity=severity)
    if coarse and family != "blobs":
        raise OptionError("{coarse} belongs to {model}; leave it out or use that model.", coarse=True, model="blobs")


def corrupt_scene(
    scene_dir: Path | str,
    out_masks: str,
    severity: str = SEVERITY,
    *,
    model: str = "blobs",
    coarse: bool = False,
    seed: int = 0,
    masks: str = GT_MASKS,
    overwrite: bool = False,
    progress: bool = True,
) -> dict:
    """Write corrupted copies of a scene's exact masks to ``scene_dir/out_masks/*.png``.

    Also writes ``corruption.json`` there (the family, its parameters and the measured error
    of every view) and returns it. The measured error is the fraction of pixels that disagree
    with the exact mask after the best renaming of IDs (see ``label_maps.matched_error``).
    View k is corrupted with the random generator seeded by ``[seed, k]``; the runs of the
    ``proposer`` family by ``[seed, RUNS_STREAM]``.
    """
    scene_dir = Path(scene_dir)
    _check(model, severity, coarse)
    check_seed(seed)
    read = mask_folder(scene_dir, masks)  # an old scene's truth lies in object_mask/
    refuse_overlap(scene_dir / plain_name(out_masks, "out_masks"), scene_inputs(scene_dir, [read]))
    scene = load_scene(scene_dir, masks=masks)
    if scene.mask_dir is None:
        raise InputError(
            f"{scene_dir / masks}: no masks to corrupt; generate the scene with `python -m dataset_tools synth`."
        )
    target = scene_dir / out_masks
    refuse_truth(target, "overwrite")
    if target.exists() and not overwrite:
        raise OutputExists(target, " or choose another {out_masks}")
    views = [(v, m) for v in scene.views if (m := v.load_mask()) is not None]
    if model == "blobs":
        params = BlobModel(**{**asdict(blobs.SEVERITIES[severity]), "coarse": coarse})
    else:
        params = proposer.SEVERITIES[severity]
        labels = sorted({int(label) for _, m in views for label in np.unique(m) if label > 0})
        runs = proposer.plan_runs(labels, len(views), params, np.random.default_rng([seed, RUNS_STREAM]))
    errors = {}
    with exclusive_folder(scene_dir, "masks"), atomic_directory(target, overwrite=overwrite) as tmp:
        for k, (view, gt) in enumerate(tqdm(views, desc=f"corrupting ({model}, {severity})", disable=not progress)):
            rng = np.random.default_rng([seed, k])
            noisy = (
                corrupt_mask(gt, params, rng) if model == "blobs" else proposer.corrupt_view(gt, k, runs, params, rng)
            )
            write_bytes_atomic(tmp / f"{view.stem}.png", encode_png(noisy))
            errors[view.stem] = matched_error(noisy, gt)
        report = {
            "model": model,
            "severity": severity,
            "seed": seed,
            "parameters": asdict(params),
            "mean_error": float(np.mean(list(errors.values()))),
            "error_per_view": errors,
        }
        write_bytes_atomic(tmp / "corruption.json", json.dumps(report, indent=2, sort_keys=True).encode())
        how = {"from_masks": masks, "model": model, "severity": severity, "coarse": coarse, "seed": seed}
        write_bytes_atomic(tmp / MANIFEST, manifest_bytes("dataset_tools corrupt", **how))
    return report
