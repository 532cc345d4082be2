"""``gsseg segment``: reassign labels for a trained run and write ``RUN/labels.npz``."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path

from dataset_tools.infra.errors import OptionError
from gsseg.render import Backend
from gsseg.render.contributions import Contributions, contribution_matrix
from gsseg.run import Run, load_run
from gsseg.segment.reassign import METHODS, MODES, Segmentation, classifier_prior, reassign
from gsseg.segment.regularize import fill_interiors, smooth_weak_labels, weak_evidence


@dataclass(frozen=True)
class LabelOptions:
    """How labels are chosen: the reassignment (method, mode, gamma_p, slack) and the 3D
    regularisation after it (``smooth``: neighbours that relabel weak Gaussians, 0 off;
    ``fill``: objects take the Gaussians they enclose). Checked when made."""

    method: str = "prior"
    mode: str = "multi"
    gamma_p: float = 0.2
    slack: float = 0.0
    smooth: int = 0
    fill: bool = False

    def __post_init__(self) -> None:
        if self.method not in METHODS:
            raise OptionError(f"{{method}}: choose one of {', '.join(METHODS)}.", method=self.method)
        if self.mode not in MODES:
            raise OptionError("{mode}: choose multi or binary.", mode=self.mode)
        if not (math.isfinite(self.gamma_p) and math.isfinite(self.slack)):
            raise OptionError("{gamma_p} / {slack}: give finite numbers.", gamma_p=self.gamma_p, slack=self.slack)
        if self.smooth < 0:
            raise OptionError("{smooth}: give 0 (off) or a number of neighbours.", smooth=self.smooth)
        if (self.smooth or self.fill) and self.mode != "multi":
            raise OptionError("{smooth} and {fill} relabel Gaussians one label each; use {mode}.", mode="multi")


def mask_contributions(
    run: Run,
    scene_dir: Path | str | None = None,
    *,
    masks: str | None = None,
    split: str = "train",
    backend: str | Backend = "cpu",
    progress: bool = True,
) -> Contributions:
    """The contribution matrix of a loaded run over the masks of ``split`` (``masks``: the
    folder, by default the one the run was trained on; no labels where no view of ``split`` has
    a mask)."""
    masks = run.voting_masks(masks)
    views = [v for v in run.scene(scene_dir, masks=masks).split(split) if v.mask_path is not None]
    contributions = contribution_matrix(run.gaussians, views, backend=backend, progress=progress)
    contributions.model, contributions.masks = run.fingerprint, masks
    return contributions


def label_gaussians(run: Run, contributions: Contributions, options: LabelOptions = LabelOptions()) -> Segmentation:
    """Every Gaussian's label from the contribution matrix and the run's classifier.

    The classifier's classes are the IDs of the masks the run was trained on; another folder
    (masks rebuilt at the run's depth jumps, ``hqmask build --depth``) numbers its objects
    anew, so where the contributions come from another folder the prior is left out:
    ``gamma_p`` is 0 and the labels record it."""
    if contributions.masks and contributions.masks != run.masks and options.method == "prior":
        options = replace(options, gamma_p=0.0)
    prior_labels, prior_probs = classifier_prior(run.gaussians.obj_feat, run.classifier)
    result = reassign(
        contributions,
        prior_labels,
        prior_probs,
        method=options.method,
        mode=options.mode,
        gamma_p=options.gamma_p,
        slack=options.slack,
    )
    means = run.gaussians.means.numpy()
    if options.smooth and len(contributions.labels):
        result = smooth_weak_labels(
            result, means, run.gaussians.opacities.detach().numpy(), weak_evidence(contributions), k=options.smooth
        )
    if options.fill:
        result = fill_interiors(result, means)
    result.model = run.fingerprint
    return result


def segment_run(
    run_dir: Path | str,
    scene_dir: Path | str | None = None,
    *,
    options: LabelOptions = LabelOptions(),
    masks: str | None = None,
    split: str = "train",
    backend: str | Backend = "auto",
    other_scene: bool = False,
    progress: bool = True,
) -> Segmentation:
    """Label every Gaussian of a run from the masks of ``split`` (the training views by
    default; ``masks``: the folder, by default the one the run was trained on) and the run's
    classifier; write ``RUN/labels.npz`` and the contribution matrix they were chosen from,
    ``RUN/contributions.npz`` (for relabelling without recomputing it); ``other_scene``: vote
    with the masks of a scene other than the run's."""
    run = load_run(run_dir, other_scene=other_scene)
    masks = run.voting_masks(masks)
    contributions = mask_contributions(run, scene_dir, masks=masks, split=split, backend=backend, progress=progress)
    if not len(contributions.labels) and options.method != "classifier":
        raise OptionError(
            f"holds no masks for the {split} views; build them with `hqmask build` or use {{method}}.",
            file=Path(scene_dir or run.record.scene) / masks,
            method="classifier",
        )
    result = label_gaussians(run, contributions, options)
    with run.folder.lock():
        run.folder.write_labels(result)
        run.folder.write_contributions(contributions)
    return result
