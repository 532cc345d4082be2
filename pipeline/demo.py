"""``gsseg demo``: the whole pipeline on an embedded default scene (or the user's), with a report.

1. a synthetic orbit scene with exact ground truth (``dataset_tools.synth``): masks are
   proposed at its full 256x256 size, the rest runs on the 128x128 copies; or the user's
   scene folder, or a folder of photos or a video made into one by structure from motion
   (``dataset_tools.sfm``);
2. masks from the weight-free ``graph`` proposer, associated across views by SfM tracks and
   cleaned (``hqmask build``);
3. 3D-GS with object features trained on those masks (CPU schedule, shortened to the
   capture, at most 30k Gaussians or twice the SfM points);
4. the masks built again, cut where the trained model's depth jumps (``gsseg render --what
   depth``, ``hqmask build --depth``): a dark head in front of a dark bush is two objects
   to colour alone, not to the depth;
5. prior-guided reassignment with the 3D regularisations (``gsseg segment --smooth 16
   --fill-interiors``): the rims and interiors that the masks leave to the background go
   with their object, so that a removal leaves no outline of it;
6. the object under a 3D point (the first object's centre) in the synthetic scene, or in
   the user's the object the photos frame, removed (what no photo saw behind it filled),
   extracted and recoloured (``gsseg edit``);
7. the report (``gseval report``) against the exact masks where the scene has them.
"""

from __future__ import annotations

import shutil
import sys
import time
import warnings
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from dataset_tools.colmap import read_model
from dataset_tools.image_files import IMAGE_SUFFIXES, image_size, write_downsampled
from dataset_tools.infra.atomic import first_missing, require_folder_path
from dataset_tools.infra.errors import InputError, OptionError
from dataset_tools.infra.interrupts import Interrupted
from dataset_tools.infra.overlap import refuse_overlap, scene_entries
from dataset_tools.scene import GT_MASKS, linked_scene
from dataset_tools.sfm import run_sfm
from dataset_tools.synth import SynthConfig, generate_scene
from eval.report import report_run
from gsseg.edits import Selection, edit_runs
from gsseg.model.ply import read_ply
from gsseg.render import Backend, get_backend
from gsseg.render.views import render_run
from gsseg.run.loaded import Run, load_run
from gsseg.segment.clicks import Click, SceneHeld
from gsseg.segment.label_options import LabelOptions
from gsseg.segment.prompts import framed_object, object_click
from gsseg.segment.reassign import Segmentation
from gsseg.segment.segment_run import masked_views, run_regions, segment_run
from gsseg.train.config import TrainConfig
from gsseg.train.trainer import train
from hqmask.build import BuildConfig, build_masks
from pipeline.demo_options import (
    EMBEDDED_ITERS,
    FULL_RUN_VIEWS,
    GAUSSIANS_PER_POINT,
    MAX_SCENE_ITERS,
    MIN_SCENE_GAUSSIANS,
    MIN_SCENE_ITERS,
    RUN_PIXELS,
    DemoOptions,
    capture_gaussians,
    capture_iters,
    capture_pixels,
)

# Masks are proposed at 256x256, where the graph proposer separates these objects well;
# training, segmentation and the report use the 128x128 copies (images_2).
DEMO_SCENE = SynthConfig(views=24, res=256, objects=4, seed=1)
DEMO_IMAGES = "images_2"
MASKS = "hqmask"
DEPTH_MASKS = "hqmask_depth"  # the masks built again at the trained model's depth jumps
# A removed object's rim and interior stay behind without the 3D regularisations (the can of
# ../shared/data/beer leaves a glassy outline); benchmarks.edit_quality measures what they cost.
DEMO_LABELS = LabelOptions(smooth=16, fill=True)


@dataclass
class DemoResult:
    out: Path
    report: Path
    edited: str  # what was edited: "object K", or the name of a click's selection
    gaussians: int  # how many Gaussians that is
    miou: float | None
    seconds: float
    warning: str | None = None  # SfM's (cameras posed on the far side or left out); an edit over most of every view
    match: int | None = None  # the ground-truth object the edited one was matched to, where there is truth
    stages: dict[str, float] = field(default_factory=dict)  # seconds of each stage, in the order run


class _StageClock:
    """The wall time of each stage of a run, measured from the end of the one before."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = {}
        self._last = time.perf_counter()

    def done(self, stage: str) -> None:
        now = time.perf_counter()
        self.seconds[stage], self._last = now - self._last, now


def _demo_prompt(
    scene_dir: Path, run: Run, segmentation: Segmentation, synth_point: np.ndarray | None, backend: Backend
) -> tuple[dict, str | None]:
    """The prompt of what the demo edits (``edit_runs``'s keywords) and a warning where it is a
    label that covers most of every view (None elsewhere): the
    synthetic scene's first object, by a 3D point at its centre; in a user's scene the object
    the photos frame (:func:`gsseg.segment.prompts.framed_object`) of those that do not cover
    most of every view (the scene, not an object in it); in a close-up, where every object
    the photos show covers most of every view, of all; where the model shows no object
    (trained too briefly), of all that hold a Gaussian; selected as a user would, by a click
    deep inside it in a test view (:func:`gsseg.segment.prompts.object_click`: the views
    decide its Gaussians, its label is their prior); where no label holds one, what a click
    at the centre of the first test view selects."""
    scene = run.scene(scene_dir)
    if synth_point is not None:
        return {"point": np.asarray(synth_point, np.float64)}, None
    regions = run_regions(run, scene_dir, backend=backend)
    scene_wide = regions.covering()
    objects = {int(o): s for o, s in zip(segmentation.objects, segmentation.selections) if s.any()}
    if not objects:
        view = scene.split("test")[0]
        return {"clicks": [Click(view.name, view.camera.width / 2, view.camera.height / 2)]}, None
    views = masked_views(run, scene_dir, masks=regions.layers[0])
    means = run.gaussians.means.numpy().astype(np.float64)
    framed = framed_object(means, {k: s for k, s in objects.items() if k not in scene_wide}, regions, views)
    if framed is None:
        framed = framed_object(means, objects, regions, views)
    if framed is None:
        framed = framed_object(means, objects, regions, views, least_shown=0.0)
    click = object_click(run.gaussians, objects[framed], scene.split("test"), backend=backend)
    prompt = {"clicks": [click]} if click is not None else {"object_id": framed}
    wide = None
    if framed in scene_wide:
        wide = (
            f"object {framed} covers most of every view: the photos are a close-up of it, or the masks "
            "joined it to what surrounds it; then select it in `gsseg view`, where shift-clicks on the "
            "surroundings carve it out (docs/segmentation.md, Clicks)."
        )
    return prompt, wide


def _edited(selection: Selection, prompt: dict) -> str:
    """What the demo edited, in words: an object by its ID, the object under one click, or
    a selection's name."""
    if selection.object_id is not None:
        return f"object {selection.object_id}"
    if len(prompt.get("clicks", ())) == 1:
        click = prompt["clicks"][0]
        return f"the object clicked in {click.view} at ({click.u:.0f}, {click.v:.0f})"
    return selection.name


def demo_images(scene: Path, max_side: int = DemoOptions.max_side) -> str:
    """The first of ``images``, ``images_2``, ``images_4``, ``images_8`` of ``scene`` whose
    longest side is at most ``max_side`` pixels (the smallest there is otherwise)."""
    present = [f for f in ("images", "images_2", "images_4", "images_8") if (scene / f).is_dir()]
    if not present:
        raise InputError(f"{scene}: no images/ folder; pass a scene folder, a folder of photos or a video.")
    for folder in present:
        first = _first_image(scene / folder)
        if first is not None and max(image_size(first)) <= max_side:
            return folder
    return present[-1]


def _first_image(folder: Path) -> Path | None:
    """The first image file of ``folder`` (sub-folders too) in name order, None if it has none."""
    return next((p for p in sorted(folder.rglob("*")) if p.suffix in IMAGE_SUFFIXES), None)


@dataclass(frozen=True)
class DemoTraining:
    """How long the demo trains and how large its model may grow: ``iters`` steps, at most
    ``max_gaussians`` Gaussians, and ``why``, a sentence for the user."""

    iters: int
    max_gaussians: int
    why: str


def demo_training(scene_dir: Path, images: str, options: DemoOptions) -> DemoTraining:
    """The demo's training on the views of ``scene_dir/images``: ``options.iters`` and
    ``options.max_gaussians`` where given; on the embedded scene :data:`EMBEDDED_ITERS` steps
    and :data:`MIN_SCENE_GAUSSIANS`; else the capture's
    (:func:`pipeline.demo_options.capture_iters` of the first view's size and the photos of
    its SfM model, :func:`pipeline.demo_options.capture_gaussians` of its points)."""
    reasons = []
    model = read_model(scene_dir / "sparse" / "0") if options.scene is not None else None
    if options.iters is not None:
        iters = options.iters
        reasons.append("steps as asked")
    elif options.scene is None:
        iters = EMBEDDED_ITERS
        reasons.append("the embedded scene's steps")
    else:
        first = _first_image(scene_dir / images)
        width, height = image_size(first) if first is not None else (0, 0)
        views = len(model.images)
        iters = capture_iters(width * height, views)
        pixels = capture_pixels(views)
        shrunk = (
            f", {FULL_RUN_VIEWS}/{views} of {RUN_PIXELS / 1e6:.0f} for {views} photos," if pixels < RUN_PIXELS else ""
        )
        reasons.append(
            f"{pixels / 1e6:.0f} million pixels in all{shrunk} at {width}x{height} a view, "
            f"{MIN_SCENE_ITERS}-{MAX_SCENE_ITERS} steps"
        )
    if options.max_gaussians is not None:
        cap = options.max_gaussians
        reasons.append("the cap as asked")
    elif options.scene is None:
        cap = MIN_SCENE_GAUSSIANS
    else:
        points = len(model.xyz)
        cap = capture_gaussians(points)
        reasons.append(f"{points:,} SfM points, room to grow them {GAUSSIANS_PER_POINT}x")
    why = "; ".join(reasons)
    return DemoTraining(iters, cap, f"training {iters} steps, at most {cap:,} Gaussians ({why})")


def masks_at_depth_jumps(
    run_dir: Path,
    scene_dir: Path,
    images: str,
    out_masks: str,
    depth_dir: Path,
    *,
    backend: str | Backend = "auto",
    progress: bool = True,
) -> Path:
    """The mask stage's second pass: the trained run's depth of every view at the size of
    ``images`` (``depth_dir/depth/<stem>.npy``), then the masks built again from it into
    ``scene_dir/out_masks`` (the ``graph`` proposer, cut at its depth jumps). Returns the mask
    folder."""
    render_run(
        run_dir, scene_dir, depth_dir, split="all", what=("depth",), images=images, backend=backend, progress=progress
    )
    return build_masks(
        scene_dir,
        BuildConfig(
            proposer="graph", associate="tracks", out_masks=out_masks, images=images, depth=str(depth_dir / "depth")
        ),
        progress=progress,
    ).out_dir


def run_demo(
    out: Path | str, options: DemoOptions = DemoOptions(), *, overwrite: bool = False, progress: bool = True
) -> DemoResult:
    """Run the pipeline into ``out``: ``out/scene`` (the synthetic scene; for photos or a video,
    the scene structure from motion makes of them; for a scene folder, links to it, so that
    its masks are written here and never into ``scene``), ``out/run``, ``out/depth`` (the
    run's depth maps), ``out/report``. Every
    option is checked before any work (:class:`pipeline.demo_options.DemoOptions`)."""
    start = time.perf_counter()
    if options.scene is not None:
        options = replace(options, scene=Path(options.scene))
    out, scene = Path(out), options.scene
    backend = get_backend(options.backend)
    cfg = TrainConfig(
        iters=options.iters,
        masks=MASKS,
        images=options.images or TrainConfig.images,
        backend=backend.name,
        max_gaussians=options.max_gaussians,  # checked here, before any work; the capture's later
    )
    if scene is not None and not scene.exists():
        raise OptionError("not found; pass a scene folder, a folder of photos or a video as {scene}.", file=scene)
    require_folder_path(out)
    if scene is not None:
        refuse_overlap(
            out, scene_entries(scene) if scene.is_dir() and (scene / "sparse").is_dir() else [("the photos", scene)]
        )
    if out.exists() and any(out.iterdir()) and not overwrite:
        raise OptionError(
            "already exists and is not empty; pass {overwrite} or choose another {out}.", file=out, overwrite=True
        )
    for owned in ("scene", "run", "depth", "report"):  # --force: the demo's own outputs, nothing else
        if (out / owned).is_symlink() or (out / owned).is_file():
            (out / owned).unlink()
        elif (out / owned).exists():
            shutil.rmtree(out / owned)
    created = first_missing(out)
    try:
        return _run_demo(out, options, cfg, backend, start, progress)
    except BaseException as e:
        if created is not None:  # a failed first run leaves nothing, so that the plain retry is not refused
            shutil.rmtree(created, ignore_errors=True)
            if isinstance(e, Interrupted):  # its advice to resume names what was just removed
                raise Interrupted(f"the demo stopped; {out} was removed, run `gsseg demo` again.") from None
        raise


def _run_demo(
    out: Path, options: DemoOptions, cfg: TrainConfig, backend: Backend, start: float, progress: bool
) -> DemoResult:
    synth_point, warning, scene = None, None, options.scene
    stages = _StageClock()
    if scene is None:
        result = generate_scene(DEMO_SCENE, out / "scene", progress=progress)
        write_downsampled(result.root / "images", result.root / DEMO_IMAGES, 2)
        scene_dir, gt_masks, mask_images = result.root, GT_MASKS, "images"
        synth_point = result.layout.objects[0].bounding_sphere[0]
        images = DEMO_IMAGES
        stages.done("synthetic scene")
    else:
        if scene.is_dir() and (scene / "sparse").is_dir():
            scene_dir = linked_scene(scene, out / "scene")
        else:  # photos or a video: structure from motion first
            posed = run_sfm(scene, out / "scene", progress=progress)
            scene_dir, warning = posed.scene, posed.warning()
            stages.done("structure from motion")
        gt_masks = None
        images = options.images or demo_images(scene_dir, options.max_side)
        mask_images = images
    plan = demo_training(scene_dir, images, options)
    if progress:
        tqdm.write(plan.why, file=sys.stderr)
    cfg = replace(cfg, images=images, iters=plan.iters, max_gaussians=plan.max_gaussians)
    build_masks(
        scene_dir,
        BuildConfig(proposer="graph", associate="tracks", out_masks=MASKS, images=mask_images),
        progress=progress,
    )
    stages.done("masks")
    run_dir = out / "run"
    train(scene_dir, run_dir, cfg, progress=progress)
    stages.done("training")
    masks_at_depth_jumps(
        run_dir, scene_dir, mask_images, DEPTH_MASKS, out / "depth", backend=backend, progress=progress
    )
    stages.done("masks at depth jumps")
    segmentation = segment_run(
        run_dir, scene_dir, options=DEMO_LABELS, masks=DEPTH_MASKS, backend=backend, progress=progress
    )
    stages.done("segmentation")
    run = load_run(run_dir)
    prompt, wide = _demo_prompt(scene_dir, run, segmentation, synth_point, backend)
    warning = " ".join(w for w in (warning, wide) if w) or None
    ops = {"remove": None, "extract": None, "recolor": (255, 40, 200)}
    with warnings.catch_warnings():
        if wide:  # the demo says it in its own words, with the viewer's shift-clicks
            warnings.simplefilter("ignore", SceneHeld)
        selection, folders = edit_runs(run_dir, ops, scene_dir=scene_dir, backend=backend, progress=progress, **prompt)
    edits = dict(zip(ops, folders))
    stages.done("edits")
    report = out / "report"
    with torch.no_grad():
        ev = report_run(
            run_dir,
            scene_dir,
            report,
            gt_masks=gt_masks,
            selection=selection,
            removal=read_ply(edits["remove"] / "gaussians.ply"),  # filled once, in gsseg edit
            backend=backend,
            progress=progress,
        )
    miou = ev.summary()["visible"]["miou"]
    stages.done("report")
    return DemoResult(
        out,
        report / "report.html",
        _edited(selection, prompt),
        int(selection.mask.sum()),
        miou,
        time.perf_counter() - start,
        warning,
        ev.id_map.get(selection.object_id or selection.main_label(segmentation.labels)),
        stages.seconds,
    )
