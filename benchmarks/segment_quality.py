"""Benchmark: segmentation quality of the reassignment methods on synthetic scenes trained
on corrupted masks. For each path (orbit, forward): masks made and corrupted at a severity
at ``--res`` (512x512), made consistent by `hqmask build --proposer existing --associate
tracks` (noise removal at its default 500 px), 3D-GS trained on the half-size images with
them, then every method (and gamma_p in {-1, 0, 0.2, 1} for `prior`) scored on the test
views with the occlusion-aware protocol (pixel label = label with the largest blended
weight) against the exact masks, IDs matched once per scene. The last column votes with the
exact masks of the training views instead of the associated ones: the score a
reassignment could reach if it undid every error the masks still carry, so its distance to
`flashsplat` bounds what the prior can gain. With several
``--train-seeds`` each scene is trained once per seed on the same masks and the table gives
the mean (the differences between methods are of the order of the spread between training
runs). Prints markdown tables and writes JSON.

    python -m benchmarks.segment_quality [--out segment_quality.json] [--iters N] [--res 512]
        [--train-seeds 0,1,2]
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import torch

from benchmarks.scenes import corrupted_scene
from dataset_tools.image_files import write_downsampled
from dataset_tools.scene import load_scene
from eval.metrics import matched_miou
from eval.report import markdown_table
from gsseg.render_views import segment_pixels
from gsseg.run_folder import load_run
from gsseg.segment.reassign import classifier_prior, reassign
from gsseg.segment.segment_run import mask_contributions
from gsseg.train import TrainConfig, train
from hqmask.build import BuildConfig, build_masks

SETTINGS = [("prior", -1.0), ("prior", 0.0), ("prior", 0.2), ("prior", 1.0), ("flashsplat", 0.0), ("classifier", 0.0)]
TRAIN_IMAGES = "images_2"  # training and scoring at half the size the masks are made at


def scores(run_dir: Path, scene: Path, masks: str, settings: list[tuple[str, float]]) -> list[float]:
    """mIoU of the test views' segments for each (method, gamma_p) of ``settings``, voting with
    ``masks``, after one Hungarian matching of IDs over the views. The contribution matrix
    is computed once for all settings."""
    run = load_run(run_dir)
    contributions = mask_contributions(run, scene, masks=masks, backend="cpu", progress=False)
    prior_labels, prior_probs = classifier_prior(run.gaussians.obj_feat, run.classifier)
    views = load_scene(scene, images=TRAIN_IMAGES).split("test")
    targets = [v.load_mask() for v in views]
    result = []
    for method, gamma_p in settings:
        labels = reassign(contributions, prior_labels, prior_probs, method=method, gamma_p=gamma_p).labels
        preds = [segment_pixels(run.gaussians, labels, v.camera, torch.as_tensor(v.cam_from_world, dtype=torch.float32),
                                backend="cpu") for v in views]
        result.append(matched_miou(preds, targets))
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="segment_quality.json")
    parser.add_argument("--iters", type=int, default=None, help="Training iterations (default: the CPU schedule).")
    parser.add_argument("--res", type=int, default=512,
                        help="Size the masks are made, corrupted and associated at; training uses half of it.")
    parser.add_argument("--severity", default="medium")
    parser.add_argument("--seed", type=int, default=0, help="Seed of the scenes and their corruption.")
    parser.add_argument("--train-seeds", default="0", help="Comma-separated training seeds; the table is their mean.")
    args = parser.parse_args()
    train_seeds = [int(x) for x in args.train_seeds.split(",")]
    table, runs = {}, {}
    with tempfile.TemporaryDirectory() as tmp:
        for path in ("orbit", "forward"):
            scene = corrupted_scene(Path(tmp), path, res=args.res, severity=args.severity, seed=args.seed)
            write_downsampled(scene / "images", scene / TRAIN_IMAGES, 2)
            build_masks(scene, BuildConfig(proposer="existing", from_masks="noisy", associate="tracks",
                                           out_masks="assoc"), progress=False)
            runs[path] = {}
            for train_seed in train_seeds:
                run = Path(tmp) / f"run_{path}_{train_seed}"
                train(scene, run, TrainConfig(iters=args.iters, images=TRAIN_IMAGES, masks="assoc", backend="cpu",
                                              seed=train_seed), progress=False)
                row = dict(zip((f"{m} {g:g}" if m == "prior" else m for m, g in SETTINGS),
                               scores(run, scene, "assoc", SETTINGS)))
                row["flashsplat, exact masks"], = scores(run, scene, "object_mask", [("flashsplat", 0.0)])
                runs[path][train_seed] = row
                print(path, train_seed, json.dumps(runs[path][train_seed]))
            table[path] = {c: sum(r[c] for r in runs[path].values()) / len(train_seeds) for c in runs[path][train_seeds[0]]}
    columns = list(next(iter(table.values())))
    print(markdown_table(["scene", *columns], [[path, *(f"{row[c]:.4f}" for c in columns)] for path, row in table.items()]))
    if len(train_seeds) > 1:
        print(markdown_table(["scene", "training seed", *columns],
                             [[path, str(seed), *(f"{row[c]:.4f}" for c in columns)]
                              for path, by_seed in runs.items() for seed, row in by_seed.items()]))
    Path(args.out).write_text(json.dumps({"mIoU": table, "per_training_seed": runs, "setup": vars(args)}, indent=2) + "\n")


if __name__ == "__main__":
    main()
