"""Benchmark: segmentation quality of the reassignment methods on synthetic scenes trained on
corrupted masks.

For each path (orbit, forward): masks made and corrupted at a severity at ``--res`` (512x512),
made consistent by ``hqmask build --proposer existing --associate tracks``, 3D-GS trained on
the half-size images with them, then every method (and gamma_p in {-1, 0, 0.2, 1} for
``prior``) scored on the test views with the occlusion-aware protocol (pixel label = label
with the largest blended weight) against the exact masks, IDs matched once per scene. The
last column votes with the exact masks of the training views instead of the associated
ones: the score a reassignment could reach if it undid every error the masks still carry,
so its distance to ``flashsplat`` bounds what the prior can gain. With several
``--train-seeds`` each scene is trained once per seed on the same masks and the table gives
the mean (the differences between methods are of the order of the spread between training
runs). Prints markdown tables and writes JSON.

    python -m benchmarks.segment_quality [--iters N] [--res 512] [--severity medium]
        [--train-seeds 0,1,2] [--out FILE]
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

from benchmarks import record
from dataset_tools.scene import GT_MASKS
from dataset_tools.synth.generator import PATHS
from eval.report import markdown_table
from gsseg.segment.label_options import LabelOptions
from gsseg.train.config import TrainConfig
from pipeline.experiment import (
    SceneSpec,
    associate_masks,
    corrupt_masks,
    segmentation_scores,
    synthetic_scene,
    train_run,
)

SETTINGS = [("prior", -1.0), ("prior", 0.0), ("prior", 0.2), ("prior", 1.0), ("flashsplat", 0.0), ("classifier", 0.0)]
EXACT = "flashsplat, exact masks"
TRAIN_IMAGES = "images_2"  # training and scoring at half the size the masks are made at


def _column(method: str, gamma_p: float) -> str:
    return f"prior {gamma_p:g}" if method == "prior" else method


def run_scene(work: Path, path: str, args: argparse.Namespace, train_seeds: list[int]) -> dict[int, dict]:
    """The scores of every setting on one scene, per training seed."""
    scene = synthetic_scene(work / path, SceneSpec(path=path, seed=args.seed, res=args.res), downsample=(2,))
    corrupt_masks(scene, "noisy", severity=args.severity, seed=args.seed)
    associate_masks(scene, "noisy", "assoc", associate="tracks")
    runs = {}
    for train_seed in train_seeds:
        run = work / f"run_{path}_{train_seed}"
        train_run(
            scene,
            run,
            TrainConfig(iters=args.iters, images=TRAIN_IMAGES, masks="assoc", backend="cpu", seed=train_seed),
        )
        summaries = segmentation_scores(run, scene, "assoc", [LabelOptions(method=m, gamma_p=g) for m, g in SETTINGS])
        row = {_column(m, g): s["visible"]["miou"] for (m, g), s in zip(SETTINGS, summaries)}
        exact = segmentation_scores(run, scene, GT_MASKS, [LabelOptions(method="flashsplat", gamma_p=0.0)])
        row[EXACT] = exact[0]["visible"]["miou"]
        runs[train_seed] = row
        print(path, train_seed, json.dumps(row))
    return runs


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--out", default=None, help="JSON file (default: benchmarks/results/segment_quality[-SEVERITY].json)."
    )
    parser.add_argument("--iters", type=int, default=None, help="Training iterations (default: the CPU schedule).")
    parser.add_argument(
        "--res",
        type=int,
        default=512,
        help="Size the masks are made, corrupted and associated at; training uses half of it.",
    )
    parser.add_argument("--severity", default="medium")
    parser.add_argument("--seed", type=int, default=0, help="Seed of the scenes and their corruption.")
    parser.add_argument("--train-seeds", default="0", help="Comma-separated training seeds; the table is their mean.")
    args = parser.parse_args()
    train_seeds = [int(x) for x in args.train_seeds.split(",")]
    with tempfile.TemporaryDirectory() as tmp:
        runs = {path: run_scene(Path(tmp), path, args, train_seeds) for path in PATHS}
    means = {
        path: {c: sum(r[c] for r in by_seed.values()) / len(by_seed) for c in next(iter(by_seed.values()))}
        for path, by_seed in runs.items()
    }
    results = {"mIoU": means, "per_training_seed": runs, "setup": vars(args)}
    print(report(results)[1])
    record.save("segment_quality", results, tag="" if args.severity == "medium" else args.severity, out=args.out)


def report(r: dict) -> tuple[str, str]:
    means, setup = r["mIoU"], r["setup"]
    columns = list(next(iter(means.values())))
    headline = ", ".join(
        f"{path}: prior 0.2 {row['prior 0.2']:.3f} / flashsplat {row['flashsplat']:.3f} / "
        f"exact-mask vote {row[EXACT]:.3f}"
        for path, row in means.items()
    )
    n = len(next(iter(r["per_training_seed"].values())))
    details = [
        f"Severity `{setup['severity']}`, masks at {setup['res']}², training on the half-size copies "
        f"({setup['iters'] or 'CPU schedule'} iterations); test-view mIoU (visible protocol), mean of {n} "
        "training seed(s):",
        "",
        markdown_table(["scene", *columns], [[p, *(f"{row[c]:.4f}" for c in columns)] for p, row in means.items()]),
    ]
    if n > 1:
        details += [
            "",
            "Per training seed:",
            "",
            markdown_table(
                ["scene", "training seed", *columns],
                [
                    [p, str(seed), *(f"{row[c]:.4f}" for c in columns)]
                    for p, by_seed in r["per_training_seed"].items()
                    for seed, row in by_seed.items()
                ],
            ),
        ]
    return headline, "\n".join(details)


if __name__ == "__main__":
    main()
