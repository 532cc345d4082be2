"""Benchmark: structure from motion time against the number of photos, exhaustive matching
against retrieval matching (``--matcher retrieval``, each photo with its 20 most alike), on
the 96 photos of ``gaussctrl_bear`` (512x512) and evenly spaced subsets of them, or any folder
of photos with SIFT on images at most ``--max-image-size`` pixels (as ``sfm`` takes it). Both
matchers run on the same SIFT features (extracted once per photo set); for each: the seconds
of every step, the images registered, and the retrieval model's cameras against the
exhaustive one's (median and largest rotation error in degrees, centre error as a share of
the cameras' extent, after a robust alignment). Prints and writes JSON.

    python -m benchmarks.sfm_speed [--photos ../shared/data/real/gaussctrl_bear/photos]
        [--counts 24,48,96] [--max-image-size 3200] [--work /tmp/sfm_speed] [--tag T] [--out FILE]
"""

from __future__ import annotations

import argparse
import json
import shutil
from pathlib import Path

import numpy as np

from benchmarks import record
from dataset_tools.scene import load_scene
from dataset_tools.sfm import SfmConfig, run_sfm
from eval.metrics import camera_errors
from eval.report import markdown_table

STEPS = ("features", "matches", "mapping", "undistort")


def subset(photos: Path, count: int, out: Path) -> Path:
    """``count`` photos spread evenly over the sorted folder ``photos``, copied to ``out``."""
    names = sorted(p.name for p in photos.iterdir() if p.suffix.lower() in (".jpg", ".jpeg", ".png"))
    out.mkdir(parents=True, exist_ok=True)
    for k in np.linspace(0, len(names) - 1, count).round().astype(int):
        shutil.copy(photos / names[k], out / names[k])
    return out


def timed_sfm(photos: Path, scene: Path, config: SfmConfig, features_from: Path | None = None) -> dict:
    """SfM with ``config`` into ``scene`` (made afresh; the features of ``features_from`` reused
    when given) and the seconds of each step, features included when reused."""
    shutil.rmtree(scene, ignore_errors=True)
    if features_from is not None:
        (scene / ".sfm").mkdir(parents=True)
        for name in ("database.db", "steps.json"):
            shutil.copy(features_from / ".sfm" / name, scene / ".sfm" / name)
    result = run_sfm(photos, scene, config, progress=False)
    steps = json.loads((scene / ".sfm" / "steps.json").read_text())
    if features_from is not None:
        steps["features"] = json.loads((features_from / ".sfm" / "steps.json").read_text())["features"]
    seconds = {f"{s}_s": float(steps[s]["seconds"]) for s in STEPS}
    pairs = (scene / ".sfm" / "pairs.txt").read_text().count("\n") if config.matcher != "exhaustive" else None
    return {"registered": result.registered, "images": result.images, "pairs": pairs, **seconds}


def compare(photos: Path, work: Path, max_image_size: int) -> dict:
    """Exhaustive and retrieval matching of the same photos, and their cameras against each other."""
    exhaustive = timed_sfm(photos, work / "exhaustive", SfmConfig(matcher="exhaustive", max_image_size=max_image_size))
    retrieval = timed_sfm(
        photos,
        work / "retrieval",
        SfmConfig(matcher="retrieval", max_image_size=max_image_size),
        features_from=work / "exhaustive",
    )
    made = {v.name: v.cam_from_world for v in load_scene(work / "retrieval", masks=None).views}
    reference = load_scene(work / "exhaustive", masks=None)
    ref = {v.name: v.cam_from_world for v in reference.views}
    names = sorted(made.keys() & ref.keys())
    rot, ctr = camera_errors([made[n] for n in names], [ref[n] for n in names])
    n = exhaustive["images"]
    exhaustive["pairs"] = n * (n - 1) // 2
    return {
        "photos": n,
        "size": [reference.views[0].camera.width, reference.views[0].camera.height],
        "exhaustive": exhaustive,
        "retrieval": retrieval,
        "rotation_deg_median": float(np.median(rot)),
        "rotation_deg_max": float(rot.max()),
        "center_error_median": float(np.median(ctr)),
        "center_error_max": float(ctr.max()),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--photos", type=Path, default=Path("../shared/data/real/gaussctrl_bear/photos"))
    parser.add_argument("--counts", default="24,48,96")
    parser.add_argument("--max-image-size", type=int, default=SfmConfig.max_image_size)
    parser.add_argument("--work", type=Path, default=Path("/tmp/sfm_speed"))
    parser.add_argument("--tag", default="", help="Suffix of the JSON file's name.")
    parser.add_argument("--out", default=None, help="JSON file (default: benchmarks/results/sfm_speed.json).")
    args = parser.parse_args()
    rows = []
    for count in (int(c) for c in args.counts.split(",")):
        work = args.work / str(count)
        rows.append(compare(subset(args.photos, count, work / "photos"), work, args.max_image_size))
        print(json.dumps(rows[-1], indent=2))
    source = {"source": str(args.photos), "max_image_size": args.max_image_size}
    record.save("sfm_speed", {**source, "rows": rows}, out=args.out, tag=args.tag)


def report(r: dict) -> tuple[str, str]:
    def total(x: dict) -> float:
        return sum(x[f"{s}_s"] for s in STEPS)

    headline = "; ".join(
        f"{x['photos']} photos: {total(x['exhaustive']):.0f} s exhaustive, {total(x['retrieval']):.0f} s retrieval "
        f"({x['retrieval']['registered']}/{x['photos']} registered)"
        for x in r["rows"]
    )

    def size(x: dict) -> str:
        if "size" not in x:
            return "-"
        sift = min(1.0, r.get("max_image_size", SfmConfig.max_image_size) / max(x["size"]))
        return f"{x['size'][0]}x{x['size'][1]} ({round(sift * x['size'][0])}x{round(sift * x['size'][1])})"

    rows = [
        [
            str(x["photos"]),
            size(x),
            matcher,
            f"{x[matcher]['registered']}/{x['photos']}",
            f"{x[matcher]['pairs']:,}",
            " / ".join(f"{x[matcher][f'{s}_s']:.0f}" for s in STEPS),
            f"{total(x[matcher]):.0f}",
            "-"
            if matcher == "exhaustive"
            else f"{x['rotation_deg_median']:.3f} / {x['rotation_deg_max']:.3f} deg, "
            f"{100 * x['center_error_median']:.2f}% / {100 * x['center_error_max']:.2f}%",
        ]
        for x in r["rows"]
        for matcher in ("exhaustive", "retrieval")
    ]
    table = markdown_table(
        [
            "photos",
            "photo size (SIFT's)",
            "matcher",
            "registered",
            "pairs matched",
            "seconds: features / matches / mapping / undistort",
            "seconds",
            "cameras against exhaustive: rotation median / max, centre median / max",
        ],
        rows,
    )
    return headline, (
        f"{r['source']}, evenly spaced subsets; both matchers on the same features (the features' "
        "seconds counted in both), on one thread (`--deterministic`).\n\n" + table
    )


if __name__ == "__main__":
    main()
