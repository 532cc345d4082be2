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

    python -m benchmarks.association_quality [--out association_quality.json] [--res 512] [--severity medium]
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.scenes import corrupted_scene
from dataset_tools.corrupt import PERMUTE_ONLY, corrupt_mask
from dataset_tools.image_files import write_png
from dataset_tools.label_maps import consistent_fraction, overlap
from dataset_tools.scene import load_scene
from hqmask.build import BuildConfig, build_masks, clean_scene_masks


def _masks(scene: Path, name: str) -> list:
    return [v.load_mask() for v in load_scene(scene, masks=name).views]


def segment_ceiling(preds: list[np.ndarray], gts: list[np.ndarray]) -> float:
    """Share of ground-truth object pixels that carry their ID when every predicted segment
    (an ID > 0 of one view) takes the ground-truth ID it overlaps most; background stays."""
    hit = total = 0
    for p, g in zip(preds, gts):
        best = overlap(p, g).argmax(1)
        best[0] = 0
        obj = g > 0
        hit += int(np.count_nonzero(best[p[obj]] == g[obj]))
        total += int(np.count_nonzero(obj))
    return hit / max(total, 1)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="association_quality.json")
    parser.add_argument("--res", type=int, default=512)
    parser.add_argument("--views", type=int, default=24)
    parser.add_argument("--severity", default="medium")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        for path in ("orbit", "forward"):
            scene = corrupted_scene(Path(tmp), path, res=args.res, severity=args.severity, seed=args.seed,
                                    views=args.views)
            truth = _masks(scene, "object_mask")
            for k, (view, mask) in enumerate(zip(load_scene(scene).views, truth)):
                write_png(scene / "permuted" / f"{view.stem}.png",
                          corrupt_mask(mask, PERMUTE_ONLY, np.random.default_rng(k)))
            row = {"input": consistent_fraction(_masks(scene, "noisy"), truth)}
            clean_scene_masks(scene, "noisy", "cleaned", progress=False)
            row["ceiling_on_cleaned_segments"] = segment_ceiling(_masks(scene, "cleaned"), truth)
            for method in ("flow", "tracks"):
                build_masks(scene, BuildConfig(proposer="existing", from_masks="noisy", associate=method, consensus=0,
                                               out_masks=f"assoc_{method}_alone"), progress=False)
                row[f"{method}_without_consensus"] = consistent_fraction(_masks(scene, f"assoc_{method}_alone"), truth)
                start = time.perf_counter()
                build_masks(scene, BuildConfig(proposer="existing", from_masks="noisy", associate=method,
                                               out_masks=f"assoc_{method}"), progress=False)
                row[method] = consistent_fraction(_masks(scene, f"assoc_{method}"), truth)
                row[f"{method}_seconds"] = time.perf_counter() - start
                build_masks(scene, BuildConfig(proposer="existing", from_masks="permuted", associate=method,
                                               out_masks=f"permuted_{method}"), progress=False)
                row[f"{method}_on_permuted_exact"] = consistent_fraction(_masks(scene, f"permuted_{method}"), truth)
            results[path] = row
            print(path, json.dumps(row))
    results["setup"] = vars(args)
    print(json.dumps(results, indent=2))
    Path(args.out).write_text(json.dumps(results, indent=2) + "\n")


if __name__ == "__main__":
    main()
