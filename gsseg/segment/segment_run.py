"""``gsseg segment``: reassign labels for a trained run and write ``RUN/labels.npz``."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from dataset_tools.infra.errors import OptionError
from dataset_tools.scene import View
from gsseg.render import Backend
from gsseg.render.contributions import Contributions, RegionWeights, contribution_matrix
from gsseg.run.loaded import Run, load_run
from gsseg.segment.label_options import LabelOptions
from gsseg.segment.reassign import Segmentation, classifier_prior, reassign
from gsseg.segment.regularize import fill_interiors, smooth_weak_labels, weak_evidence


def masked_views(
    run: Run, scene_dir: Path | str | None = None, *, masks: str | None = None, split: str = "train"
) -> list[View]:
    """The views of ``split`` that have a mask in ``masks`` (the folder, by default the one the
    run was trained on): the views a run's contributions and region weights are computed on,
    in their order."""
    return [v for v in run.scene(scene_dir, masks=run.voting_masks(masks)).split(split) if v.mask_path is not None]


def mask_contributions(
    run: Run,
    scene_dir: Path | str | None = None,
    *,
    masks: str | None = None,
    split: str = "train",
    backend: str | Backend = "cpu",
    regions: bool = False,
    progress: bool = True,
) -> Contributions:
    """The contribution matrix of a loaded run over the masks of ``split`` (``masks``: the
    folder, by default the one the run was trained on; no labels where no view of ``split`` has
    a mask), with each view's weights kept apart as well when ``regions`` is asked for."""
    masks = run.voting_masks(masks)
    views = masked_views(run, scene_dir, masks=masks, split=split)
    contributions = contribution_matrix(run.gaussians, views, backend=backend, regions=regions, progress=progress)
    contributions.model, contributions.masks = run.fingerprint, masks
    if contributions.regions is not None:
        contributions.regions.layers, contributions.regions.model = (masks,), run.fingerprint
    return contributions


def region_layers(run: Run, masks: str | None = None) -> list[str]:
    """The mask folders whose regions a click is lifted through: the voting masks ``masks``
    (default: the run's), then the masks the run was trained on where those differ (the masks
    of colour beside the masks cut at the depth jumps), so that an object one pass holds and the
    other swallowed is still found."""
    voting = run.voting_masks(masks)
    return [voting] + ([run.masks] if run.masks and run.masks != voting else [])


def mask_regions(
    run: Run,
    scene_dir: Path | str | None = None,
    *,
    masks: str | None = None,
    split: str = "train",
    backend: str | Backend = "cpu",
    first: Contributions | None = None,
    progress: bool = True,
) -> RegionWeights:
    """The run's :class:`RegionWeights` over the :func:`region_layers` of ``masks``; ``first``:
    contributions of the first layer computed already with their regions. A layer whose folder
    the scene lacks is left out."""
    parts = []
    for k, layer in enumerate(region_layers(run, masks)):
        if k == 0 and first is not None and first.regions is not None:
            parts.append(first.regions)
            continue
        if k and not (Path(scene_dir or run.record.scene) / layer).is_dir():
            continue
        parts.append(
            mask_contributions(
                run, scene_dir, masks=layer, split=split, backend=backend, regions=True, progress=progress
            ).regions
        )
    return RegionWeights.stack(parts)


def label_gaussians(run: Run, contributions: Contributions, options: LabelOptions = LabelOptions()) -> Segmentation:
    """Every Gaussian's label from the contribution matrix and the run's classifier.

    The classifier's classes are the IDs of the masks the run was trained on; another folder
    (masks rebuilt at the run's depth jumps, ``hqmask build --depth``) numbers its objects
    anew, so where the contributions come from another folder the prior is left out:
    ``gamma_p`` is 0 and the labels record it."""
    if contributions.masks and contributions.masks != run.masks and options.method == "prior":
        options = replace(options, gamma_p=0.0)
    prior_labels, prior_probs = classifier_prior(run.gaussians.obj_feat, run.classifier)
    result = reassign(contributions, prior_labels, prior_probs, options)
    means = run.gaussians.means.numpy()
    if options.smooth and len(contributions.labels):
        result = smooth_weak_labels(
            result, means, run.gaussians.opacities.detach().numpy(), weak_evidence(contributions), k=options.smooth
        )
    if options.fill:
        result = fill_interiors(result, means)
    result.model = run.fingerprint
    return result


def run_regions(
    run: Run, scene_dir: Path | str | None = None, *, backend: str | Backend = "cpu", progress: bool = False
) -> RegionWeights:
    """``RUN/regions.npz`` where it belongs to the run's model; else the region weights of the
    masks the run's labels were voted with (recorded in ``RUN/contributions.npz``, else the
    run's own), computed and written there (runs segmented before region weights existed)."""
    cached = run.folder.read_regions()
    if cached is not None and cached.model == run.fingerprint:
        return cached
    contributions = run.folder.read_contributions()
    voted = contributions.masks if contributions is not None and contributions.masks else None
    regions = mask_regions(run, scene_dir, masks=voted, backend=backend, progress=progress)
    with run.folder.lock():
        run.folder.write_regions(regions)
    return regions


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
    classifier; write ``RUN/labels.npz``, the contribution matrix they were chosen from,
    ``RUN/contributions.npz`` (for relabelling without recomputing it), and the region weights
    of :func:`mask_regions`, ``RUN/regions.npz`` (what clicks select with); ``other_scene``: vote
    with the masks of a scene other than the run's."""
    run = load_run(run_dir, other_scene=other_scene)
    masks = run.voting_masks(masks)
    contributions = mask_contributions(
        run, scene_dir, masks=masks, split=split, backend=backend, regions=True, progress=progress
    )
    if not len(contributions.labels) and options.method != "classifier":
        raise OptionError(
            f"holds no masks for the {split} views; build them with `hqmask build` or use {{method}}.",
            file=Path(scene_dir or run.record.scene) / masks,
            method="classifier",
        )
    result = label_gaussians(run, contributions, options)
    regions = mask_regions(
        run, scene_dir, masks=masks, split=split, backend=backend, first=contributions, progress=progress
    )
    with run.folder.lock():
        run.folder.write_labels(result)
        run.folder.write_contributions(contributions)
        run.folder.write_regions(regions)
    return result
