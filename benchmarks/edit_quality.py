"""Benchmark: edits judged by the pictures they leave, against ground truth.

For each path (orbit, forward) and mask set (``exact``; ``medium`` and ``high``: corrupted,
then made consistent by ``hqmask build``), 3D-GS is trained on the half-size images once per
training seed; then every ground-truth object is removed and extracted with the labels of
each setting (``prior`` or ``flashsplat``; without and with the 3D regularisations of
``gsseg segment``: ``--smooth 16``, ``--fill-interiors``, both), and the test views are
compared with the generator's views without the object and of the object alone:

- removal: PSNR over the view, over the region the object covered (where a ghost shows),
  over the part of it whose background a training view saw, over the rest (unseen), and
  outside the region; SSIM over the region, and with ``--lpips FILE`` (an LPIPS network,
  ``gseval export-lpips``) LPIPS around it; the ghost share (the selection's weight in the
  training views that the Gaussians left behind carry); for the ``prior`` labels and the
  demo's (``+ smooth + fill``) also with the removal filled (``gsseg edit``'s default,
  :mod:`gsseg.fill`), with the fill's time per object;
- extraction: IoU of its alpha >= 0.5 silhouette with the whole true silhouette, PSNR inside
  it (on white), and the leak, the share of its opacity outside the silhouette dilated by 2 px.

With ``--knn-reg W`` the ``medium`` scenes are also trained with Gaussian Grouping's 3D
identity term at weight W. Prints markdown tables and writes JSON.

    python -m benchmarks.edit_quality [--iters 1000] [--res 512] [--train-seeds 0,1]
        [--masks exact,medium,high] [--knn-reg 1.0] [--lpips FILE] [--out FILE]
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import numpy as np

from benchmarks import record
from dataset_tools.infra.overlap import refuse_overlap
from dataset_tools.scene import GT_MASKS
from dataset_tools.synth.edit_truth import write_edit_truth
from eval.edit_scores import edit_rows, summarize_edits
from eval.evaluate import evaluate
from eval.lpips import LPIPS
from eval.report import markdown_table
from gsseg.fill_options import FillOptions
from gsseg.run.loaded import load_run
from gsseg.segment.label_options import LabelOptions
from gsseg.segment.segment_run import label_gaussians, mask_contributions
from gsseg.train.config import TrainConfig
from pipeline.experiment import SceneSpec, associate_masks, corrupt_masks, synthetic_scene, train_run

TRAIN_IMAGES = "images_2"
SETTINGS = {
    "prior": LabelOptions(),
    "prior + smooth": LabelOptions(smooth=16),
    "prior + fill": LabelOptions(fill=True),
    "prior + smooth + fill": LabelOptions(smooth=16, fill=True),
    "flashsplat": LabelOptions(method="flashsplat", gamma_p=0.0),
    "flashsplat + smooth + fill": LabelOptions(method="flashsplat", gamma_p=0.0, smooth=16, fill=True),
}
FILLED = ("prior", "prior + smooth + fill")  # also scored filled: the default labels, the demo's


def masks_for(scene: Path, kind: str, seed: int) -> str:
    if kind == "exact":
        return GT_MASKS
    corrupt_masks(scene, f"noisy_{kind}", severity=kind, seed=seed)
    return associate_masks(scene, f"noisy_{kind}", f"assoc_{kind}", associate="tracks")


def score_run(run_dir: Path, scene: Path, masks: str, lpips: LPIPS | None = None) -> dict:
    """Every setting's edit scores (and visible mIoU) on one trained run (LPIPS with ``lpips``)."""
    run = load_run(run_dir)
    contributions = mask_contributions(run, scene, masks=masks, backend="cpu", progress=False)
    views = run.scene(scene, masks=GT_MASKS).split("test")
    out = {}
    for name, options in SETTINGS.items():
        segmentation = label_gaussians(run, contributions, options)
        evaluation, _ = evaluate(
            run, segmentation, views, with_truth=True, scene=str(scene), split="test", backend="cpu", progress=False
        )
        fill = FillOptions() if name in FILLED else None
        rows = edit_rows(run, segmentation, views, scene, evaluation.id_map, fill=fill, lpips=lpips)
        out[name] = {
            **summarize_edits(rows),
            "miou": evaluation.summary()["visible"]["miou"],
            "worst_removal_psnr_seen": min(
                (r["removal"]["psnr_seen"] for r in rows if r["removal"]["psnr_seen"] is not None), default=None
            ),
            "worst_extraction_iou": min((r["extraction"]["iou"] for r in rows), default=None),
            "worst_leak": max((r["extraction"]["leak"] for r in rows), default=None),
        }
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=None, help="JSON file (default: benchmarks/results/edit_quality.json).")
    parser.add_argument("--iters", type=int, default=1000)
    parser.add_argument("--res", type=int, default=512, help="Size masks are made at; training uses half of it.")
    parser.add_argument("--seed", type=int, default=0, help="Seed of the scenes and their corruption.")
    parser.add_argument("--train-seeds", default="0,1")
    parser.add_argument("--masks", default="exact,medium,high")
    parser.add_argument("--paths", default="orbit,forward")
    parser.add_argument("--knn-reg", type=float, default=0.0, help="Also train medium with the 3D identity term.")
    parser.add_argument("--lpips", default=None, help="LPIPS network (gseval export-lpips): removals' LPIPS too.")
    args = parser.parse_args()
    if args.lpips:  # the JSON is written after each run: never over the network it reads
        refuse_overlap(record.out_path("edit_quality", out=args.out), [("the LPIPS network", Path(args.lpips))])
    lpips = LPIPS(args.lpips) if args.lpips else None  # a bad file fails before any training
    seeds = [int(s) for s in args.train_seeds.split(",")]
    results: dict = {"runs": {}, "setup": vars(args)}
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        for path in args.paths.split(","):
            scene = synthetic_scene(work / path, SceneSpec(path=path, seed=args.seed, res=args.res), downsample=(2,))
            write_edit_truth(scene, images=TRAIN_IMAGES, progress=False)
            for kind in args.masks.split(","):
                masks = masks_for(scene, kind, args.seed)
                variants = [("", 0.0)] + ([("knn", args.knn_reg)] if args.knn_reg and kind == "medium" else [])
                for tag, knn in variants:
                    for seed in seeds:
                        name = f"{path}/{kind}{'+' + tag if tag else ''}/{seed}"
                        run = work / name.replace("/", "_")
                        train_run(
                            scene,
                            run,
                            TrainConfig(
                                iters=args.iters,
                                images=TRAIN_IMAGES,
                                masks=masks,
                                backend="cpu",
                                seed=seed,
                                knn_reg=knn,
                            ),
                        )
                        results["runs"][name] = score_run(run, scene, masks, lpips)
                        print(
                            name,
                            json.dumps(
                                {
                                    k: {m: round(v, 4) if isinstance(v, float) else v for m, v in s.items()}
                                    for k, s in results["runs"][name].items()
                                }
                            ),
                            flush=True,
                        )
                        record.save("edit_quality", results, out=args.out)  # each finished run, as it finishes
    print(report(results)[1])
    record.save("edit_quality", results, out=args.out)


def _mean(values: list[float | None]) -> float | None:
    kept = [v for v in values if v is not None]
    return float(np.mean(kept)) if kept else None


def _spread(values: list[float | None]) -> str:
    kept = [v for v in values if v is not None]
    if not kept:
        return "n/a"
    return f"{np.mean(kept):.3f}" + (f" ({min(kept):.3f}-{max(kept):.3f})" if len(kept) > 1 else "")


def report(r: dict) -> tuple[str, str]:
    groups: dict[tuple[str, str], list[dict]] = {}
    for name, settings in r["runs"].items():
        path, kind, _ = name.split("/")
        groups.setdefault((path, kind), []).append(settings)
    rows = []
    for (path, kind), runs in groups.items():
        for setting in runs[0]:
            cells = [run[setting] for run in runs]
            rows.append(
                [
                    path,
                    kind,
                    setting,
                    _spread([c["removal_psnr_seen"] for c in cells]),
                    _spread([c["removal_psnr_region"] for c in cells]),
                    _spread([c["extraction_iou"] for c in cells]),
                    _spread([c["extraction_iou_seen"] for c in cells]),
                    _spread([c["leak"] for c in cells]),
                    _spread([c["extraction_psnr_inside"] for c in cells]),
                    _spread([c["miou"] for c in cells]),
                    _spread([c.get("ghost_share_after") for c in cells]),
                ]
            )
    headline = "; ".join(
        f"{path}, {kind} masks, {setting}: removal {_mean([run[setting]['removal_psnr_seen'] for run in runs]):.1f} dB "
        f"where the background was seen, extraction IoU {_mean([run[setting]['extraction_iou'] for run in runs]):.3f} "
        f"({_mean([run[setting]['extraction_iou_seen'] for run in runs]):.3f} over the seen part), "
        f"leak {100 * _mean([run[setting]['leak'] for run in runs]):.1f}%"
        for (path, kind), runs in groups.items()
        for setting in ("prior", "prior + smooth")
        if setting in runs[0]
    )
    table = markdown_table(
        [
            "path",
            "masks",
            "labels",
            "removal PSNR, seen (dB)",
            "removal PSNR, region (dB)",
            "extraction IoU",
            "extraction IoU, seen part",
            "leak",
            "extraction PSNR inside (dB)",
            "mIoU",
            "ghost share",
        ],
        rows,
    )
    filled = [
        [
            path,
            kind,
            setting,
            *(
                f"{_spread([c.get(f'removal_{k}') for c in cells])} -> {_spread([c.get(f'filled_{k}') for c in cells])}"
                for k in ("psnr_region", "psnr_unseen", "psnr_seen", "psnr_outside", "ssim_region", "lpips_region")
            ),
            _spread([c["fill_seconds"] for c in cells]),
        ]
        for (path, kind), runs in groups.items()
        for setting in FILLED
        if setting in runs[0] and "filled_psnr_region" in runs[0][setting]
        for cells in [[run[setting] for run in runs]]
    ]
    fill_headline = "; ".join(f"{row[0]}, {row[1]} masks, removal over the region {row[3]} dB filled" for row in filled)
    fill_table = markdown_table(
        [
            "path",
            "masks",
            "labels",
            "region (dB)",
            "unseen part (dB)",
            "seen part (dB)",
            "outside the region (dB)",
            "region SSIM",
            "LPIPS around the region",
            "fill time per object (s)",
        ],
        filled,
    )
    return "; ".join(x for x in (headline, fill_headline) if x), (
        "Means over the ground-truth objects and test views; the mean over training seeds with their "
        "range in brackets. The seen part of a silhouette is what some training view saw of the object "
        "(a forward capture never sees what other objects hide from every view); the IoU over it leaves "
        "the rest out. The ghost share: the selection's weight in the training views that the Gaussians "
        f"its removal leaves carry (n/a: not measured then).\n\n{table}"
        + (
            "\n\nThe removal without and with the fill (plain -> filled): PSNR over the region the object "
            "covered, its parts whose background no training view saw and some did, and the rest of the "
            "view; SSIM over the region and LPIPS over the box around it (n/a: no network given, or "
            f"not measured then).\n\n{fill_table}"
            if filled
            else ""
        )
    )


if __name__ == "__main__":
    main()
