"""Benchmark: the click rules on synthetic scenes, held out from the real captures they were
chosen on, with exact ground truth for every object.

For each path and scene seed, the generator's scene is trained as ``benchmarks.edit_quality``
trains it (``--iters`` steps on the half-size images, the ``medium`` masks made consistent by
``hqmask build``), labelled with the demo's options (``--smooth 16 --fill-interiors``), and
every ground-truth object is selected by ten clicks under each protocol of
``benchmarks.real_scenes`` (docs/evaluation.md): the run's own masks (``masks``), half the
object given away to the background (``half``), the object joined to its surroundings
(``joined``), and the clicks alone (``alone``); in one view, and alternating with the view
that looks from farthest away. The object's views are those where it covers at least
:data:`MIN_COVER` of the frame; the first of them by name is clicked first, the others scored.

The headline is the worst object, not the mean. Finished scenes and runs in ``--work`` are
reused. Prints and writes JSON.

    python -m benchmarks.click_quality [--paths orbit,forward] [--seeds 0,1] [--iters 1000]
        [--protocols masks,half,joined,alone] [--objects 1,2] [--work DIR] [--tag T] [--out FILE]
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from benchmarks import record
from benchmarks.edit_quality import TRAIN_IMAGES, masks_for
from benchmarks.real_scenes import (
    CURVE,
    MAX_CLICKS,
    TARGET,
    TrueObject,
    half_given_away,
    interactive,
    joined_to_surroundings,
)
from dataset_tools.scene import GT_MASKS, View
from eval.report import markdown_table
from gsseg.run.loaded import Run, load_run
from gsseg.segment.clicks import ClickSelector
from gsseg.segment.segment_run import segment_run
from gsseg.train.config import TrainConfig
from pipeline.demo import DEMO_LABELS
from pipeline.experiment import SceneSpec, synthetic_scene, train_run

MASKS = "medium"
MIN_COVER = 0.01  # share of the frame an object must cover in a view for it to be clicked or scored

Given = Callable[[Run, list[View], dict[str, np.ndarray], TrueObject], tuple[ClickSelector, np.ndarray]]
PROTOCOLS: dict[str, tuple[bool, Given | None]] = {  # name: (the clicks alone, the masks given)
    "masks": (False, None),
    "half": (False, half_given_away),
    "joined": (False, joined_to_surroundings),
    "alone": (True, None),
}


def object_truth(ids: dict[str, np.ndarray], obj: int) -> dict[str, np.ndarray]:
    """(H, W) bool the exact mask of object ``obj`` in each view where it covers at least
    :data:`MIN_COVER` of the frame, by view name, of the views' exact ID maps ``ids``."""
    truth = {name: mask == obj for name, mask in ids.items()}
    return {name: mask for name, mask in truth.items() if mask.mean() >= MIN_COVER}


def object_curves(run: Run, views: list[View], truth: dict[str, np.ndarray], protocols: list[str]) -> dict:
    """Ten clicks under each of ``protocols``, in one view and alternating with a second:
    ``{protocol: {"one_view": curve, "alternating": curve}}`` (the curve: mIoU after each
    click, NoC@90, largest fall)."""
    views = [v for v in views if v.name in truth]
    obj = TrueObject.of(run, views, truth)
    out: dict = {"views": len(views), "ceiling_miou": obj.ceiling(run, views, truth)}
    for name in protocols:
        alone, given = PROTOCOLS[name]
        out[name] = {}
        for mode, alternate in (("one_view", False), ("alternating", True)):
            if alternate and len(views) < 3:  # a view to score besides the two clicked
                continue
            curve = interactive(
                run,
                views,
                truth,
                past_target=True,
                alone=alone,
                alternate=alternate,
                given=given(run, views, truth, obj) if given else None,
            )
            out[name][mode] = {k: curve[k] for k in CURVE}
    return out


def run_scene(path: str, seed: int, work: Path, iters: int, protocols: list[str], objects: list[int] | None) -> dict:
    """Train (or reuse) the scene's run, label it, and click every ground-truth object."""
    root = work / f"{path}-{seed}"
    scene = synthetic_scene(root / "scene", SceneSpec(path=path, seed=seed, res=512), downsample=(2,))
    masks = masks_for(scene, MASKS, seed)
    run_dir = root / "run"
    start = time.perf_counter()
    train_run(scene, run_dir, TrainConfig(iters=iters, images=TRAIN_IMAGES, masks=masks, backend="cpu", seed=0))
    train_s = time.perf_counter() - start
    segment_run(run_dir, scene, options=DEMO_LABELS, masks=masks, backend="cpu", progress=False)
    run = load_run(run_dir)
    views = run.scene(scene, masks=GT_MASKS).views
    ids = {v.name: v.load_mask() for v in views}
    present = sorted({int(i) for mask in ids.values() for i in np.unique(mask)} - {0})
    result = {"path": path, "seed": seed, "gaussians": len(run.gaussians), "train_s": train_s, "objects": {}}
    for obj in objects or present:
        truth = object_truth(ids, obj)
        if len(truth) < 2:  # nothing to score besides the clicked view
            continue
        start = time.perf_counter()
        result["objects"][str(obj)] = {**object_curves(run, views, truth, protocols), "s": time.perf_counter() - start}
        print(f"{path}-{seed} object {obj}: {json.dumps(result['objects'][str(obj)])}", flush=True)
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--paths", default="orbit,forward")
    parser.add_argument("--seeds", default="0,1", help="Seeds of the scenes (and their masks' corruption).")
    parser.add_argument("--iters", type=int, default=1000)
    parser.add_argument("--protocols", default=",".join(PROTOCOLS), help=f"Of {', '.join(PROTOCOLS)}.")
    parser.add_argument("--objects", default=None, help="Ground-truth object IDs (default: every one).")
    parser.add_argument("--work", type=Path, default=Path("/tmp/click_quality"))
    parser.add_argument("--tag", default="", help="Suffix of the JSON file's name.")
    parser.add_argument("--out", default=None, help="JSON file (default: benchmarks/results/click_quality.json).")
    args = parser.parse_args()
    protocols = args.protocols.split(",")
    unknown = sorted(set(protocols) - set(PROTOCOLS))
    if unknown:
        parser.error(f"--protocols: {', '.join(unknown)} unknown; choose from {', '.join(PROTOCOLS)}.")
    objects = [int(k) for k in args.objects.split(",")] if args.objects else None
    record.refuse_out_inside(parser, "click_quality", args.work, tag=args.tag, out=args.out)
    results: dict = {"scenes": [], "protocols": protocols}
    for path in args.paths.split(","):
        for seed in (int(s) for s in args.seeds.split(",")):
            results["scenes"].append(run_scene(path, seed, args.work, args.iters, protocols, objects))
            record.save("click_quality", results, tag=args.tag, out=args.out)  # each finished scene
    print(report(results)[1])


def _curves(r: dict, protocol: str, mode: str) -> list[tuple[str, dict]]:
    return [
        (f"{s['path']}-{s['seed']} #{k}", o[protocol][mode])
        for s in r["scenes"]
        for k, o in s["objects"].items()
        if mode in o.get(protocol, {})
    ]


def report(r: dict) -> tuple[str, str]:
    def noc(c: dict) -> str:
        return str(c["noc90"]) if c["noc90"] is not None else f">{MAX_CLICKS}"

    summary, headline = [], []
    for protocol in r["protocols"]:
        for mode in ("one_view", "alternating"):
            curves = _curves(r, protocol, mode)
            if not curves:
                continue
            last = [c["miou_by_clicks"][-1] for _, c in curves]
            worst_name, worst = min(curves, key=lambda nc: nc[1]["miou_by_clicks"][-1])
            steep_name, steep = max(curves, key=lambda nc: nc[1]["largest_fall"])
            reached = sum(c["noc90"] is not None and c["noc90"] <= 3 for _, c in curves)
            summary.append(
                [
                    protocol,
                    mode.replace("_", " "),
                    str(len(curves)),
                    f"{np.mean([c['miou_by_clicks'][0] for _, c in curves]):.3f}",
                    f"{np.mean(last):.3f}",
                    f"{worst['miou_by_clicks'][-1]:.3f} ({worst_name})",
                    f"{reached}/{len(curves)}",
                    f"{sum(x >= TARGET for x in last)}/{len(curves)}",
                    f"{steep['largest_fall']:.3f} ({steep_name})",
                ]
            )
            headline.append(
                f"{protocol}, {mode.replace('_', ' ')}: mean {np.mean(last):.3f} after the 10th click, "
                f"worst {worst['miou_by_clicks'][-1]:.3f} ({worst_name}), largest fall {steep['largest_fall']:.3f}"
            )
    per_object = [
        [
            f"{s['path']}-{s['seed']}",
            k,
            str(o["views"]),
            f"{o['ceiling_miou']:.3f}",
            *(
                "; ".join(
                    f"{' '.join(f'{m:.2f}' for m in o[p][mode]['miou_by_clicks'])} (NoC {noc(o[p][mode])})"
                    for mode in ("one_view", "alternating")
                    if mode in o[p]
                )
                if p in o
                else "n/a"
                for p in r["protocols"]
            ),
        ]
        for s in r["scenes"]
        for k, o in s["objects"].items()
    ]
    return "; ".join(headline), (
        "Every ground-truth object of the synthetic scenes, ten clicks each (docs/evaluation.md). "
        "Over the objects: the mean mIoU after the first and the tenth click, the worst object after "
        f"the tenth, how many reach {TARGET} within 3 clicks and by the tenth, and the largest fall "
        "of the mIoU after one click.\n\n"
        + markdown_table(
            [
                "protocol",
                "clicks",
                "objects",
                "mean, 1st click",
                "mean, 10th click",
                "worst, 10th click",
                "NoC@90 <= 3",
                f">= {TARGET} by the 10th",
                "largest fall",
            ],
            summary,
        )
        + "\n\nPer object: the mIoU after each click in one view; alternating views.\n\n"
        + markdown_table(
            ["scene", "object", "views", "ceiling", *r["protocols"]],
            per_object,
        )
    )


if __name__ == "__main__":
    main()
