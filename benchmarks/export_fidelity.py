"""Benchmark: does an export look in another viewer as it looks here? Each run is exported
(PLY, with and without the environment's shell) and every test view is rendered from the file
by the standard 3D-GS conventions (:mod:`eval.standard_render`, on black) and compared with
``gsseg render`` of the run over its learned environment. Prints and writes JSON.

    python -m benchmarks.export_fidelity --run demo/run [--run beer_run ...] [--out FILE]
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks import record
from eval.report import markdown_table
from eval.standard_render import read_splats, render_reference
from gsseg.export import export_run
from gsseg.run.loaded import load_run


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    return float(-10 * np.log10(max(((a - b) ** 2).mean(), 1e-12)))


def fidelity(run_dir: Path, split: str = "test") -> dict:
    """PSNR of the standard renderer on the exported PLY against ``gsseg render``, per view of
    ``split``, with and without the shell, and the Gaussian counts."""
    run = load_run(run_dir)
    views = run.scene().split(split)
    ours = [run.render(v).rgb.clamp(0, 1).numpy() for v in views]
    result = {"run": str(run_dir), "views": [v.name for v in views], "gaussians": len(run.gaussians)}
    with tempfile.TemporaryDirectory() as tmp:
        for environment in (True, False):
            splats = read_splats(export_run(run_dir, Path(tmp) / f"{environment}.ply", environment=environment))
            start = time.perf_counter()
            scores = [
                psnr(
                    mine,
                    np.clip(
                        render_reference(
                            splats,
                            v.camera.fx,
                            v.camera.fy,
                            v.camera.cx,
                            v.camera.cy,
                            v.camera.width,
                            v.camera.height,
                            v.cam_from_world,
                        ),
                        0,
                        1,
                    ),
                )
                for v, mine in zip(views, ours)
            ]
            key = "with_environment" if environment else "without_environment"
            result[key] = {
                "psnr": scores,
                "mean_psnr": float(np.mean(scores)),
                "exported": len(splats["means"]),
                "seconds_per_view": (time.perf_counter() - start) / len(views),
            }
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--run", action="append", required=True, type=Path, help="A run folder (repeatable).")
    parser.add_argument("--split", default="test")
    parser.add_argument("--out", default=None, help="JSON file (default: benchmarks/results/export_fidelity.json).")
    args = parser.parse_args()
    results = {"runs": []}
    for run in args.run:
        results["runs"].append(fidelity(run, args.split))
        print(json.dumps(results["runs"][-1], indent=2))
    record.save("export_fidelity", results, out=args.out)


def report(r: dict) -> tuple[str, str]:
    headline = "; ".join(
        f"{Path(x['run']).parent.name}/{Path(x['run']).name} "
        f"{x['with_environment']['mean_psnr']:.1f} dB with the shell "
        f"({x['without_environment']['mean_psnr']:.1f} without)"
        for x in r["runs"]
    )
    rows = [
        [
            x["run"],
            str(len(x["views"])),
            f"{x['gaussians']:,}",
            f"{x['with_environment']['exported']:,}",
            f"{x['with_environment']['mean_psnr']:.2f} (min {min(x['with_environment']['psnr']):.2f})",
            f"{x['without_environment']['mean_psnr']:.2f}",
        ]
        for x in r["runs"]
    ]
    table = markdown_table(
        ["run", "test views", "Gaussians", "exported with the shell", "PSNR with the shell (dB)", "PSNR without (dB)"],
        rows,
    )
    return headline, (
        "The exported PLY rendered by `eval.standard_render` (the 3D-GS rasterizer's conventions, "
        "on black) against `gsseg render` over the learned environment, mean over the test views. "
        "The runs are those of `gsseg demo` and of `gsseg demo --scene ../shared/data/beer --images "
        "images_4 --out /tmp/beerdemo`.\n\n" + table
    )


if __name__ == "__main__":
    main()
