"""``gsseg segment``: reassign labels for a trained run and write ``RUN/labels.npz``."""

from __future__ import annotations

from pathlib import Path

from dataset_tools.errors import InputError
from gsseg.render import Backend
from gsseg.render.contributions import Contributions, MaskedView, contribution_matrix
from gsseg.run import Run, load_run
from gsseg.segment.reassign import Segmentation, classifier_prior, reassign


def mask_contributions(run: Run, scene_dir: Path | str | None = None, *, masks: str = "object_mask",
                       split: str = "train", backend: str | Backend = "cpu", progress: bool = True) -> Contributions:
    """The contribution matrix of a loaded run over the masks of ``split`` (no labels where
    no view of ``split`` has a mask)."""
    views = [MaskedView(v.camera, v.cam_from_world, m) for v in run.scene(scene_dir, masks=masks).split(split)
             if (m := v.load_mask()) is not None]
    return contribution_matrix(run.gaussians, views, backend=backend, progress=progress)


def segment_run(run_dir: Path | str, scene_dir: Path | str | None = None, *, method: str = "prior",
                mode: str = "multi", gamma_p: float = 0.2, slack: float = 0.0, masks: str = "object_mask",
                split: str = "train", backend: str | Backend = "auto", progress: bool = True) -> Segmentation:
    """Label every Gaussian of a run from the masks of ``split`` (the training views by
    default) and the run's classifier; write ``RUN/labels.npz``."""
    run = load_run(run_dir)
    contributions = mask_contributions(run, scene_dir, masks=masks, split=split, backend=backend, progress=progress)
    if not len(contributions.labels) and method != "classifier":
        raise InputError(f"{Path(scene_dir or run.record.scene) / masks} holds no masks for the {split} views; "
                         "build them with `hqmask build` or use --method classifier.")
    prior_labels, prior_probs = classifier_prior(run.gaussians.obj_feat, run.classifier)
    result = reassign(contributions, prior_labels, prior_probs, method=method, mode=mode, gamma_p=gamma_p,
                      slack=slack)
    result.save(run.folder.labels)
    return result
