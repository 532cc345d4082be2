"""The steps of an experiment on synthetic scenes with exact ground truth, shared by the paper
tables and the benchmarks. Each step reuses what an earlier call finished, so an interrupted
experiment resumes:

    scene = synthetic_scene(work / "orbit", SceneSpec(path="orbit", res=512), downsample=(2,))
    corrupt_masks(scene, "noisy", severity="medium", seed=0)
    associate_masks(scene, "noisy", "assoc", associate="tracks")
    train_run(scene, work / "run", TrainConfig(images="images_2", masks="assoc"))
    summaries = segmentation_scores(work / "run", scene, "assoc", [LabelOptions(), LabelOptions(method="flashsplat")])
"""

from __future__ import annotations

import shutil
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from dataset_tools.corruption import corrupt_scene
from dataset_tools.image_files import write_downsampled
from dataset_tools.label_maps import consistent_fraction
from dataset_tools.scene import GT_MASKS, load_scene, save_scene
from dataset_tools.synth import SynthConfig, generate_scene
from eval.evaluate import evaluate
from eval.metrics import matched_miou, mean_iou, psnr, ssim
from gsseg.render import Backend, to_uint8
from gsseg.render.pixel_labels import classify_pixels
from gsseg.run.folder import RunFolder
from gsseg.run.loaded import load_run
from gsseg.segment.label_options import LabelOptions
from gsseg.segment.segment_run import label_gaussians, mask_contributions
from gsseg.train.config import TrainConfig
from gsseg.train.trainer import train
from hqmask.build import BuildConfig, build_masks


@dataclass(frozen=True)
class SceneSpec:
    """A synthetic scene of the generator (see :class:`dataset_tools.synth.SynthConfig`)."""

    path: str = SynthConfig.path
    seed: int = SynthConfig.seed
    res: int = SynthConfig.res
    views: int = SynthConfig.views
    objects: int = SynthConfig.objects

    @property
    def name(self) -> str:
        return f"{self.path}-{self.seed}"

    def synth_config(self) -> SynthConfig:
        return SynthConfig(views=self.views, res=self.res, objects=self.objects, path=self.path, seed=self.seed)


def synthetic_scene(root: Path, spec: SceneSpec, *, downsample: tuple[int, ...] = ()) -> Path:
    """The scene folder of ``spec`` at ``root`` with its exact masks in ``gt_mask/`` and an
    ``images_N`` copy for every N of ``downsample``; made once, reused after."""
    root = Path(root)
    if not (root / "sparse").is_dir():
        generate_scene(spec.synth_config(), root, overwrite=root.exists(), progress=False)
    for factor in downsample:
        if not (root / f"images_{factor}").is_dir():
            write_downsampled(root / "images", root / f"images_{factor}", factor)
    return root


def shuffled_copy(scene: Path, out: Path, *, seed: int = 0) -> Path:
    """A copy of ``scene`` at ``out`` whose views carry their files under shuffled names (as a
    phone's burst or a merged folder names them), with every mask folder renamed alike and
    the same views held out; made once."""
    out = Path(out)
    if (out / "sparse").is_dir():
        return out
    source = load_scene(scene, masks=None)
    order = np.random.default_rng(seed).permutation(len(source.views))
    name_of = {v.name: f"{order[k]:04d}{Path(v.name).suffix}" for k, v in enumerate(source.views)}
    renamed = replace(
        source,
        views=[replace(v, name=name_of[v.name]) for v in source.views],
        test_names=frozenset(name_of[n] for n in source.test_names),
    )
    save_scene(renamed, out)
    folders = [p for p in Path(scene).iterdir() if p.is_dir() and not p.name.startswith(".")]
    for folder in (p for p in folders if p.name not in ("images", "sparse")):
        for view in source.views:
            mask = folder / f"{Path(view.name).stem}.png"
            if mask.is_file():
                (out / folder.name).mkdir(exist_ok=True)
                shutil.copyfile(mask, out / folder.name / f"{Path(name_of[view.name]).stem}.png")
    return out


def corrupt_masks(scene: Path, out_masks: str, **options) -> str:
    """``scene/out_masks``: the exact masks corrupted by
    :func:`dataset_tools.corruption.corrupt_scene` with ``options``; made once."""
    if not (Path(scene) / out_masks).is_dir():
        corrupt_scene(scene, out_masks, progress=False, **options)
    return out_masks


def associate_masks(scene: Path, source: str, out_masks: str, *, associate: str = "tracks", **options) -> str:
    """``scene/out_masks``: ``hqmask build --proposer existing --from-masks source`` (noise
    removal, association, consensus; ``options`` are further :class:`BuildConfig` fields);
    made once."""
    if not (Path(scene) / out_masks).is_dir():
        build_masks(
            scene,
            BuildConfig(proposer="existing", from_masks=source, associate=associate, out_masks=out_masks, **options),
            progress=False,
        )
    return out_masks


def mask_scores(scene: Path, masks: str, *, truth: str = GT_MASKS) -> dict[str, float]:
    """A mask folder against the exact masks over every view: ID consistency (one matching
    of IDs for the scene) and the matched mIoU."""
    preds = [v.load_mask() for v in load_scene(scene, masks=masks).views]
    gts = [v.load_mask() for v in load_scene(scene, masks=truth).views]
    return {"consistency": consistent_fraction(preds, gts), "miou": matched_miou(preds, gts)}


def train_run(scene: Path, run: Path, cfg: TrainConfig, *, progress: bool = False) -> float | None:
    """Train ``cfg`` on ``scene`` into ``run`` unless it is finished already (resuming one that
    was interrupted). Returns the seconds spent, None when the run was reused."""
    folder = RunFolder(run)
    if folder.finished:
        return None
    start = time.perf_counter()
    train(scene, run, cfg, resume=bool(folder.checkpoint_files()), progress=progress)
    return time.perf_counter() - start


def segmentation_scores(
    run_dir: Path,
    scene: Path,
    masks: str,
    settings: list[LabelOptions],
    *,
    truth: str = GT_MASKS,
    backend: str | Backend = "cpu",
) -> list[dict]:
    """For each of ``settings``: the run's Gaussians labelled from ``masks`` as ``gsseg
    segment`` labels them (:func:`gsseg.segment.segment_run.label_gaussians`, one contribution
    matrix for every setting), scored on the test views against ``truth``. Returns
    :meth:`eval.evaluate.Evaluation.summary` of each setting."""
    run = load_run(run_dir)
    contributions = mask_contributions(run, scene, masks=masks, backend=backend, progress=False)
    views = run.scene(scene, masks=truth).split("test")
    out = []
    for options in settings:
        segmentation = label_gaussians(run, contributions, options)
        evaluation, _ = evaluate(
            run, segmentation, views, with_truth=True, scene=str(scene), split="test", backend=backend, progress=False
        )
        out.append(evaluation.summary())
    return out


def test_view_scores(run_dir: Path, scene: Path, *, backend: str | Backend = "cpu") -> dict[str, float]:
    """Test-view PSNR and SSIM of the run's renders and, where the scene has masks, the mIoU of
    the classifier's label at every pixel against them (IDs as trained, no matching)."""
    run = load_run(run_dir)
    views = run.scene(scene, masks=run.config.masks).split("test")
    renders = [run.render(v, with_features=run.config.masks is not None, backend=backend) for v in views]
    rgb = [to_uint8(r.rgb) for r in renders]
    images = [v.load_image() for v in views]
    out = {
        "test_views": len(views),
        "test_psnr": float(np.mean([psnr(a, b) for a, b in zip(rgb, images)])),
        "test_ssim": float(np.mean([ssim(a, b) for a, b in zip(rgb, images)])),
    }
    truth = [v.load_mask() for v in views]
    if run.config.masks is not None and all(t is not None for t in truth):
        labels = [classify_pixels(r.features, run.classifier.to(r.features.device)).cpu().numpy() for r in renders]
        out["test_miou"] = mean_iou([label.astype(np.uint8) for label in labels], truth)
    return out
