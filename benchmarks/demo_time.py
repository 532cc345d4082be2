"""Benchmark: ``gsseg demo --scene PHOTOS`` on real captures, from the photos to the report.

Each capture's photos (``REAL/<capture>/photos``) run through the whole demo from scratch in
``WORK/<capture>``, structure from motion included, as a user's would: the wall time of every
stage, the training the demo chose, the test PSNR of its model and what it edited. The times
are the point, so run it alone on the machine. The demo's aim: a capture of up to 100 photos
within 10 minutes on 2 cores (docs/training.md).

    python -m benchmarks.demo_time [--real DIR] [--scenes A,B] [--work W] [--tag T] [--out FILE]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from benchmarks.record import save
from dataset_tools.colmap import read_model
from dataset_tools.image_files import IMAGE_SUFFIXES
from dataset_tools.infra.errors import InputError
from eval.report import markdown_table
from gsseg.run.loaded import load_run
from pipeline.demo import run_demo
from pipeline.demo_options import DemoOptions


def run_capture(name: str, real: Path, work: Path) -> dict:
    """The demo on ``real/name/photos`` into ``work/name`` (replaced): its seconds in all and
    per stage, steps, Gaussians, test PSNR and edit; or why it was refused (photos structure
    from motion cannot pose, a ``work`` holding the photos)."""
    photos = real / name / "photos"
    count = sum(1 for p in photos.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
    try:
        result = run_demo(work / name, DemoOptions(scene=photos), overwrite=True, progress=False)
    except InputError as refused:
        return {"scene": name, "photos": count, "refused": str(refused)}
    run = load_run(result.out / "run")
    evaluation = run.folder.read_evaluation()
    return {
        "scene": name,
        "photos": count,
        "posed": len(read_model(result.out / "scene" / "sparse" / "0").images),
        "iters": run.config.timing.iters,
        "max_gaussians": run.config.timing.max_gaussians,
        "gaussians": len(run.gaussians),
        "test_psnr": evaluation["summary"]["psnr"],
        "seconds": result.seconds,
        "stages": result.stages,
        "edited": result.edited,
        "edited_gaussians": result.gaussians,
        "warning": result.warning,
    }


def report(r: dict) -> tuple[str, str]:
    refused = [x for x in r["scenes"] if "refused" in x]
    ran = [x for x in r["scenes"] if "refused" not in x]
    slowest = max(ran, key=lambda x: x["seconds"], default=None)
    headline = "; ".join(
        ([f"slowest: {slowest['scene']}, {slowest['seconds'] / 60:.1f} min"] if slowest else [])
        + [f"{x['scene']}: {x['photos']} photos, {x['seconds'] / 60:.1f} min, {x['test_psnr']:.2f} dB" for x in ran]
        + [f"{x['scene']}: refused" for x in refused]
    )
    stages = list(dict.fromkeys(s for x in ran for s in x["stages"]))
    rows = [
        [
            x["scene"],
            f"{x['posed']}/{x['photos']}",
            f"{x['iters']}, {x['max_gaussians']:,}",
            f"{x['gaussians']:,}",
            f"{x['test_psnr']:.2f}",
            f"{x['seconds'] / 60:.1f}",
            *(f"{x['stages'][s] / 60:.1f}" if s in x["stages"] else "" for s in stages),
            f"{x['edited']} ({x['edited_gaussians']:,} Gaussians)" + (" with a warning" if x["warning"] else ""),
        ]
        for x in ran
    ]
    table = markdown_table(
        [
            "scene",
            "photos posed",
            "steps, cap",
            "Gaussians",
            "test PSNR",
            "minutes in all",
            *(f"{s}, min" for s in stages),
            "edited",
        ],
        rows,
    )
    not_run = "".join(f"\n\n{x['scene']}: refused: {x['refused']}" for x in refused)
    details = (
        "`gsseg demo --scene REAL/<capture>/photos` from scratch, each capture in turn; the wall time of "
        "every stage as the demo prints it.\n\n" + table + not_run
    )
    return headline, details


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--real", type=Path, default=Path("../shared/data/real"))
    parser.add_argument("--scenes", default="statue")
    parser.add_argument("--work", type=Path, default=Path("/tmp/demo_time"))
    parser.add_argument("--tag", default="", help="Suffix of the JSON file's name.")
    parser.add_argument("--out", default=None, help="JSON file (default: benchmarks/results/demo_time.json).")
    args = parser.parse_args()
    results = {"scenes": []}
    for name in args.scenes.split(","):
        results["scenes"].append(run_capture(name, args.real, args.work))
        print(json.dumps(results["scenes"][-1], indent=2))
        save("demo_time", results, tag=args.tag, out=args.out)


if __name__ == "__main__":
    main()
