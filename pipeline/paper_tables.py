"""``gseval paper-tables``: the analogs of the paper's tables on synthetic scenes with exact
ground truth.

For every scene of the setup (orbit and forward camera paths, several seeds) the masks come
in four kinds, each trained on:

- ``exact``: the generator's masks;
- ``coarse``: low-resolution boundaries (as SAM's against SAM-HQ's), made consistent and
  cleaned by ``hqmask build --proposer existing``;
- ``noisy``: corrupted at ``medium`` (wrong boundaries, spurious islands, merged and split
  objects, IDs permuted per view), used as they are;
- ``hqmask``: the noisy masks after ``hqmask build`` (noise removal and association).

Tables:

1. training masks -> test PSNR / SSIM (and mIoU of ``prior``): Table 1 (coarse vs clean),
   and the effect of noise removal and association on the 3D result;
2. the masks themselves against the exact ones: noisy, after noise removal alone, after
   noise removal and association (scene-level ID consistency and matched mIoU);
3. reassignment methods on the ``hqmask`` run: ``flashsplat`` vs ``prior`` vs
   ``classifier``, mIoU / mAcc in both protocols, per scene (Table 3);
4. the gamma_p ablation of ``prior`` on the same run.

Work goes to ``OUT/work/`` and is reused when the command runs again (finished runs are not
retrained), so an interrupted full run resumes. Results: ``OUT/paper_tables.md`` and
``OUT/paper_tables.json``.
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from dataset_tools.corruption import SEVERITY
from dataset_tools.infra.atomic import require_folder_path, write_bytes_atomic
from dataset_tools.infra.engine import Engine
from dataset_tools.scene import GT_MASKS, IMAGES
from dataset_tools.synth.generator import PATHS
from eval.evaluate import PROTOCOLS
from eval.report import markdown_table
from gsseg.render import Backend, get_backend
from gsseg.segment.label_options import LabelOptions
from gsseg.train.config import TrainConfig
from hqmask.build import clean_scene_masks
from hqmask.cleanup import PAPER_MIN_AREA
from pipeline.experiment import (
    SceneSpec,
    associate_masks,
    corrupt_masks,
    mask_scores,
    segmentation_scores,
    synthetic_scene,
    train_run,
)

TRAINING_MASKS = ("exact", "coarse", "noisy", "hqmask")
MASK_FOLDERS = {"exact": GT_MASKS, "coarse": "coarse_hqmask", "noisy": "noisy", "hqmask": "noisy_hqmask"}
METHODS = (("flashsplat", 0.0), ("classifier", 0.0), ("prior", 0.2))
GAMMAS = (-1.0, 0.0, 0.2, 1.0)
MASK_SCORES = ("noisy", "noisy_cleaned", "noisy_hqmask", "coarse", "coarse_hqmask")  # Table 2's rows


@dataclass(frozen=True)
class TableSetup:
    """The scenes and schedule behind the tables."""

    paths: tuple[str, ...]
    seeds: tuple[int, ...]
    res: int
    views: int
    objects: int
    iters: int | None  # None: the CPU default schedule
    images: str = IMAGES  # trained on: ``images`` or a downsampled copy such as ``images_2``
    severity: str = SEVERITY
    min_area: int = PAPER_MIN_AREA  # noise removal, at the resolution the masks are made and corrupted at
    max_gaussians: int | None = None  # None: the schedule's cap

    @property
    def scenes(self) -> list[tuple[str, int]]:
        return [(p, s) for p in self.paths for s in self.seeds]


SETUPS = {
    # Masks are made, corrupted and cleaned at 256x256 (the corruption's speckles are sized
    # against the 500 px cleanup threshold); quick trains on the 128x128 copies, and stops
    # densifying at 20k Gaussians (a 128x128 view has 16k pixels).
    "quick": TableSetup(
        paths=PATHS,
        seeds=(0,),
        res=256,
        views=16,
        objects=4,
        iters=300,
        images="images_2",
        max_gaussians=20_000,
    ),
    "full": TableSetup(paths=PATHS, seeds=(0, 1, 2), res=256, views=24, objects=6, iters=None),
}


def _prepare_scene(root: Path, path: str, seed: int, setup: TableSetup) -> Path:
    """The synthetic scene with every mask folder of :data:`MASK_FOLDERS` (and the
    noise-removal-only masks), made once and reused."""
    factor = () if setup.images == IMAGES else (int(setup.images.rsplit("_", 1)[1]),)
    spec = SceneSpec(path=path, seed=seed, res=setup.res, views=setup.views, objects=setup.objects)
    scene = synthetic_scene(root / "scene", spec, downsample=factor)
    corrupt_masks(scene, "coarse", severity="low", coarse=True, seed=seed)
    corrupt_masks(scene, "noisy", severity=setup.severity, seed=seed)
    if not (scene / "noisy_cleaned").is_dir():
        clean_scene_masks(scene, "noisy", "noisy_cleaned", min_area=setup.min_area, progress=False)
    for src in ("coarse", "noisy"):
        associate_masks(scene, src, f"{src}_hqmask", associate="tracks", min_area=setup.min_area)
    return scene


@dataclass(frozen=True)
class _Task:
    """One piece of the tables' work on one scene (``kind``: a training mask kind, for the
    training tasks)."""

    root: Path
    path: str
    seed: int
    setup: TableSetup
    backend: str
    kind: str = ""


def _scene_task(task: _Task) -> dict:
    """Make the scene and its masks; score the masks."""
    scene = _prepare_scene(task.root, task.path, task.seed, task.setup)
    return {name: mask_scores(scene, name) for name in MASK_SCORES}


def _training_task(task: _Task) -> dict:
    """Train on one kind of masks and score the run."""
    scene, run = task.root / "scene", task.root / f"run_{task.kind}"
    setup = task.setup
    seconds = train_run(
        scene,
        run,
        TrainConfig(
            iters=setup.iters,
            images=setup.images,
            masks=MASK_FOLDERS[task.kind],
            backend=task.backend,
            max_gaussians=setup.max_gaussians,
        ),
    )
    # The pipeline segments with the masks it trained on; `noisy` ones cannot be voted
    # with (their IDs differ per view), so that run is segmented by its classifier alone.
    method = LabelOptions(method="classifier", gamma_p=0.0) if task.kind == "noisy" else LabelOptions()
    (summary,) = segmentation_scores(run, scene, MASK_FOLDERS[task.kind], [method], backend=task.backend)
    return {
        "psnr": summary["psnr"],
        "ssim": summary["ssim"],
        "miou": summary["visible"]["miou"],
        "method": method.method,
        "train_seconds": seconds,
    }


def _methods_task(task: _Task) -> dict:
    """The reassignment methods and the gamma_p ablation on the ``hqmask`` run."""
    settings = [LabelOptions(method=m, gamma_p=g) for m, g in METHODS] + [LabelOptions(gamma_p=g) for g in GAMMAS]
    summaries = segmentation_scores(
        task.root / "run_hqmask", task.root / "scene", MASK_FOLDERS["hqmask"], settings, backend=task.backend
    )
    return {
        "methods": {m: {p: s[p] for p in PROTOCOLS} for (m, _), s in zip(METHODS, summaries)},
        "gamma_p": {f"{g:g}": {p: s[p] for p in PROTOCOLS} for g, s in zip(GAMMAS, summaries[len(METHODS) :])},
    }


def _f(x: float | None, digits: int = 3) -> str:
    return "n/a" if x is None or not np.isfinite(x) else f"{x:.{digits}f}"


def _mean(values: list[float]) -> float:
    return float(np.mean(values))


def render_tables(scenes: dict[str, dict], setup: TableSetup) -> str:
    """The four tables as markdown, per scene and averaged."""
    names = list(scenes)
    schedule = "the CPU default schedule" if setup.iters is None else f"{setup.iters} iterations"
    if setup.max_gaussians is not None:
        schedule += f", at most {setup.max_gaussians} Gaussians"
    parts = [
        f"Scenes: {', '.join(names)} ({setup.res}x{setup.res}, {setup.views} views, {setup.objects} objects; "
        f"masks made at that size, noise removal min_area {setup.min_area} px; trained on `{setup.images}` "
        f"for {schedule}; test views: LLFF hold-out)."
    ]

    rows = []
    for kind in TRAINING_MASKS:
        cells = [scenes[n]["training"][kind] for n in names]
        rows.append(
            [
                kind,
                _f(_mean([c["psnr"] for c in cells]), 2),
                _f(_mean([c["ssim"] for c in cells])),
                _f(_mean([c["miou"] for c in cells])),
                cells[0]["method"],
            ]
        )
    parts.append(
        "### Table 1: training masks (test views, mean over scenes)\n\n"
        + markdown_table(["training masks", "PSNR", "SSIM", "mIoU (visible)", "labels by"], rows)
    )

    labels = {
        "noisy": "noisy (medium)",
        "noisy_cleaned": "noisy + noise removal",
        "noisy_hqmask": "noisy + noise removal + association",
        "coarse": "coarse",
        "coarse_hqmask": "coarse + noise removal + association",
    }
    rows = [
        [
            label,
            _f(_mean([scenes[n]["masks"][k]["consistency"] for n in names])),
            _f(_mean([scenes[n]["masks"][k]["miou"] for n in names])),
        ]
        for k, label in labels.items()
    ]
    parts.append(
        "### Table 2: 2D masks against the exact masks (all views, mean over scenes)\n\n"
        + markdown_table(["masks", "ID consistency", "mIoU"], rows)
    )

    head = ["scene"] + [f"{m} {p}" for m, _ in METHODS for p in ("mIoU", "mAcc")]
    for protocol in PROTOCOLS:
        rows = [
            [n] + [_f(scenes[n]["methods"][m][protocol][k]) for m, _ in METHODS for k in ("miou", "macc")]
            for n in names
        ]
        rows.append(
            ["mean"]
            + [
                _f(_mean([scenes[n]["methods"][m][protocol][k] for n in names]))
                for m, _ in METHODS
                for k in ("miou", "macc")
            ]
        )
        parts.append(
            f"### Table 3: reassignment methods, `{protocol}` protocol (trained on hqmask masks)\n\n"
            + markdown_table(head, rows)
        )

    gammas = [f"{g:g}" for g in GAMMAS]
    rows = [[n] + [_f(scenes[n]["gamma_p"][g][p]["miou"]) for g in gammas for p in PROTOCOLS] for n in names]
    rows.append(
        ["mean"] + [_f(_mean([scenes[n]["gamma_p"][g][p]["miou"] for n in names])) for g in gammas for p in PROTOCOLS]
    )
    parts.append(
        "### Table 4: gamma_p ablation of `prior` (mIoU, visible / extracted)\n\n"
        + markdown_table(["scene"] + [f"gamma_p {g} {p[:3]}" for g in gammas for p in PROTOCOLS], rows)
    )
    return "\n\n".join(parts) + "\n"


def paper_tables(
    out: Path | str,
    *,
    setup: TableSetup = SETUPS["full"],
    backend: str | Backend = "auto",
    engine: Engine = Engine(),
    progress: bool = True,
) -> Path:
    """Run the tables' experiments on ``setup`` (one of :data:`SETUPS` or your own), reusing
    finished work in ``out/work``, and write ``out/paper_tables.md`` and
    ``out/paper_tables.json``. Returns the markdown path.

    The work is three rounds of independent tasks on ``engine``: the scenes and their masks,
    then one training per scene and mask kind, then the reassignment methods per scene."""
    out = Path(out)
    require_folder_path(out)
    backend = get_backend(backend)
    start = time.perf_counter()
    names = [f"{path}-{seed}" for path, seed in setup.scenes]
    tasks = [
        _Task(out / "work" / name, path, seed, setup, backend.name) for name, (path, seed) in zip(names, setup.scenes)
    ]
    masks = engine.map(_scene_task, tasks, desc="scenes and masks", progress=progress)
    trainings = engine.map(
        _training_task, [replace(t, kind=k) for t in tasks for k in TRAINING_MASKS], desc="trainings", progress=progress
    )
    methods = engine.map(_methods_task, tasks, desc="reassignment methods", progress=progress)
    scenes = {}
    for i, name in enumerate(names):
        done = trainings[i * len(TRAINING_MASKS) : (i + 1) * len(TRAINING_MASKS)]
        scenes[name] = {"masks": masks[i], "training": dict(zip(TRAINING_MASKS, done)), **methods[i]}
    markdown = "## Paper tables\n\n" + render_tables(scenes, setup)
    write_bytes_atomic(out / "paper_tables.md", markdown.encode())
    data = {
        "setup": {**asdict(setup), "backend": backend.name},
        "seconds": time.perf_counter() - start,
        "scenes": scenes,
    }
    write_bytes_atomic(out / "paper_tables.json", (json.dumps(data, indent=2) + "\n").encode())
    return out / "paper_tables.md"
