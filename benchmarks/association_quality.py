"""Benchmark: multi-view ID consistency after `hqmask build --proposer existing` on masks
corrupted at a severity, for `flow` and `tracks`, on orbit and forward scenes, beside the
corrupted input; and on the exact masks with IDs permuted per view (association alone).
Consistency = share of ground-truth object pixels carrying their matched ID, with one
Hungarian matching for the whole scene. Each method with its multi-view consensus (the
default) and without. For reference, the ceiling of association on the input after noise
removal: every segment of every view given the ground-truth ID it overlaps most, the best
any choice of IDs for those segments can score (a method passes it only by changing
segments: `tracks` splits a segment whose SfM points belong to two objects, and the
consensus relabels pixels by the views around them). Prints and writes JSON.

    python -m benchmarks.association_quality [--res 512] [--views 24] [--severity medium] [--seed 0] [--out FILE]
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks import record
from dataset_tools.corruption import PERMUTE_ONLY, corrupt_mask
from dataset_tools.image_files import write_png
from dataset_tools.scene import GT_MASKS, load_scene
from dataset_tools.synth.generator import PATHS
from eval.metrics import segment_ceiling
from eval.report import markdown_table
from hqmask.build import clean_scene_masks
from hqmask.build_options import ASSOCIATIONS
from pipeline.experiment import SceneSpec, associate_masks, corrupt_masks, mask_scores, synthetic_scene


def _masks(scene: Path, name: str) -> list[np.ndarray]:
    return [v.load_mask() for v in load_scene(scene, masks=name).views]


def run_path(root: Path, path: str, args: argparse.Namespace) -> dict:
    scene = synthetic_scene(root / path, SceneSpec(path=path, seed=args.seed, res=args.res, views=args.views))
    corrupt_masks(scene, "noisy", severity=args.severity, seed=args.seed)
    truth = _masks(scene, GT_MASKS)
    for k, (view, mask) in enumerate(zip(load_scene(scene).views, truth)):
        write_png(scene / "permuted" / f"{view.stem}.png", corrupt_mask(mask, PERMUTE_ONLY, np.random.default_rng(k)))
    row = {"input": mask_scores(scene, "noisy")["consistency"]}
    clean_scene_masks(scene, "noisy", "cleaned", progress=False)
    row["ceiling_on_cleaned_segments"] = segment_ceiling(_masks(scene, "cleaned"), truth)
    for method in (a for a in ASSOCIATIONS if a != "auto"):
        associate_masks(scene, "noisy", f"assoc_{method}_alone", associate=method, consensus=0)
        row[f"{method}_without_consensus"] = mask_scores(scene, f"assoc_{method}_alone")["consistency"]
        start = time.perf_counter()
        associate_masks(scene, "noisy", f"assoc_{method}", associate=method)
        row[f"{method}_seconds"] = time.perf_counter() - start
        row[method] = mask_scores(scene, f"assoc_{method}")["consistency"]
        associate_masks(scene, "permuted", f"permuted_{method}", associate=method)
        row[f"{method}_on_permuted_exact"] = mask_scores(scene, f"permuted_{method}")["consistency"]
    print(path, json.dumps(row))
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--out", default=None, help="JSON file (default: benchmarks/results/association_quality[-seedN].json)."
    )
    parser.add_argument("--res", type=int, default=512)
    parser.add_argument("--views", type=int, default=24)
    parser.add_argument("--severity", default="medium")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        results = {path: run_path(Path(tmp), path, args) for path in PATHS}
    results["setup"] = vars(args)
    print(report(results)[1])
    record.save("association_quality", results, tag=f"seed{args.seed}" if args.seed else "", out=args.out)


def report(r: dict) -> tuple[str, str]:
    paths = [p for p in r if p != "setup"]
    headline = ", ".join(
        f"{p}: tracks {r[p]['tracks']:.3f}, flow {r[p]['flow']:.3f} (ceiling {r[p]['ceiling_on_cleaned_segments']:.3f})"
        for p in paths
    )
    columns = [
        "input",
        "ceiling_on_cleaned_segments",
        "tracks",
        "tracks_without_consensus",
        "flow",
        "flow_without_consensus",
        "tracks_on_permuted_exact",
        "flow_on_permuted_exact",
    ]
    s = r["setup"]
    table = markdown_table(["path", *columns], [[p, *(f"{r[p][c]:.3f}" for c in columns)] for p in paths])
    return headline, (
        f"{s['views']} views at {s['res']}², masks corrupted at `{s['severity']}`, scene seed "
        f"{s['seed']}; share of object pixels with their ID after one matching per scene.\n\n{table}"
    )


if __name__ == "__main__":
    main()
