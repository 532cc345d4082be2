"""Benchmark: real photos with object masks drawn by people (``../shared/data/real``), through
the demo's path: photos -> ``sfm`` -> ``hqmask build`` -> ``gsseg train`` -> the masks built
again at the run's depth jumps (``gsseg render --what depth``, ``hqmask build --depth``) ->
``gsseg segment --smooth 16 --fill-interiors`` -> clicks, scored as SPIn-NeRF / NVOS score a
selection (docs/evaluation.md):

- **single click**: one click in the first view at the deepest point of the person's mask;
  the IoU and pixel accuracy of the selected Gaussians' render against the mask in every
  other view (mIoU, mAcc);
- **NoC@90**: clicks added in the first view, each at the deepest pixel of the largest error
  region there (positive in a miss, negative in a false positive: ``gsseg edit --click`` /
  ``--exclude-click``), until the mIoU over the other views reaches 0.90 (at most 10; all 10
  with ``--past-target``, to see how later clicks behave), and the largest fall of the mIoU
  after a click;
- **the masks**: per view the IoU of the mask ID that best covers the person's mask, of the
  union of the IDs mostly inside it, and how often the best ID is the same one; for the
  masks of colour alone and for those cut at the depth jumps.
- **the clicks alone**: the same ten clicks where the masks say nothing (each view one region,
  one label, object features of zero: what weight-free masks give on a capture they read as
  one region, a plant and the wall behind it), so that the clicks carve the object alone
  (:meth:`gsseg.segment.clicks.ClickSelector._carved`);
- **half the object given away**: the same ten clicks where every view's masks hold one half
  of the object (its Gaussians on one side of their median along their longest axis) and
  give the other to the background, with no object features (a box's lid joined to the
  bench under it: :func:`half_given_away`); the first click deep inside the kept half;
- **joined to its surroundings**: the same ten clicks where every view's masks join the object
  to the Gaussians around it, as many as it has (tools and the table under them as one
  region, with no object features: :func:`joined_to_surroundings`);
- **the clicks in two views**: the same ten clicks, with the masks and alone, where those after
  the first go in turn to the view that looks from farthest away and to the first, as a user
  turns the model in the viewer (:func:`farthest_view`); the views other than the two are
  scored;
- **the options**: the single-click mIoU under ``gsseg segment``'s defaults as well;
- **the ceiling**: the mIoU of the Gaussians whose weight falls mostly inside the people's
  masks over the views, what any selection of the model can reach;
- **the object left by its removal**: the share of those Gaussians' weight inside the
  people's masks that the single click's removal (with what served it alone, as ``gsseg edit
  --op remove`` takes it) leaves in the scene: its ghost.

``--seed`` sets the training seed, ``--tag`` the JSON file's suffix: the same command with
other seeds (and another ``--work``) shows the run-to-run spread.

The people's masks are drawn on the photos; they are carried into each undistorted view
through the camera that SfM estimated for the photo. Every stage's wall time is recorded;
finished stages in ``--work`` are reused. Prints and writes JSON.

    python -m benchmarks.real_scenes [--real ../shared/data/real] [--scenes statue,dtu_scan24]
        [--work /tmp/real_scenes] [--iters N] [--max-gaussians N] [--demo] [--past-target] [--seed 0]
        [--tag T] [--out FILE]

``--demo`` trains what ``gsseg demo`` chooses for each capture (:func:`pipeline.demo.demo_training`).
"""

from __future__ import annotations

import argparse
import json
import shutil
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import torch
from scipy import ndimage
from scipy.spatial import cKDTree

from benchmarks import record
from dataset_tools import colmap
from dataset_tools.image_files import read_mask
from dataset_tools.infra.errors import InputError
from dataset_tools.scene import View, load_scene
from dataset_tools.sfm import run_sfm
from eval.metrics import binary_scores
from eval.report import markdown_table
from gsseg.render import Backend, get_backend
from gsseg.render.contributions import MaskedView, RegionWeights, contribution_matrix
from gsseg.render.pixel_labels import segment_pixels
from gsseg.run.loaded import Run, load_run
from gsseg.segment.clicks import ClickEvidence, ClickSelector
from gsseg.segment.prompts import click_evidence, deepest_pixel
from gsseg.segment.segment_run import run_regions, segment_run
from gsseg.segment.served import complete_selection
from gsseg.train.config import TrainConfig
from gsseg.train.trainer import train
from hqmask.build import BuildConfig, build_masks
from pipeline.demo import DEMO_LABELS, DEPTH_MASKS, MASKS, demo_images, demo_training, masks_at_depth_jumps
from pipeline.demo_options import DemoOptions

TARGET = 0.90
MAX_CLICKS = 10
CURVE = ("miou_by_clicks", "noc90", "largest_fall")  # what each protocol keeps of a click curve


def people_masks(scene_dir: Path, images: str, drawn: Path) -> dict[str, np.ndarray]:
    """The people's masks (PNG 0/255, the photo's stem) in each undistorted view of the scene
    that SfM made, by view name: (H, W) bool."""
    sfm = scene_dir / ".sfm"
    model = json.loads((sfm / "steps.json").read_text())["mapping"]["model"]
    photos = {im.name: im.camera for im in colmap.read_model(sfm / "sparse" / model).images}
    out = {}
    for view in load_scene(scene_dir, images=images, masks=None).views:
        path = drawn / f"{Path(view.name).stem}.png"
        if not path.is_file() or view.name not in photos:
            continue
        mask = read_mask(path) > 127
        source = colmap.resize_source_camera(photos[view.name], mask.shape[1], mask.shape[0])
        maps = colmap.undistortion_maps(source, view.camera)
        out[view.name] = colmap.remap(mask.astype(np.uint8), maps, nearest=True).astype(bool)
    return out


def posed_scene(photos: Path, out: Path) -> Path:
    """The scene folder ``sfm`` makes of ``photos`` at ``out``, made once and then reused."""
    if not (out / "scene.json").is_file():
        run_sfm(photos, out)
    return out


def rendered_labels(run: Run, labels: np.ndarray, view: View, backend: str | Backend = "cpu") -> np.ndarray:
    """(H, W) the label of the Gaussians (``labels`` (N,) uint8) that win each pixel's blended
    weight (``render --what segments``)."""
    backend = get_backend(backend)
    pose = torch.as_tensor(view.cam_from_world, dtype=torch.float32, device=backend.device)
    return segment_pixels(run.gaussians_on(backend.device), labels, view.camera, pose, backend=backend)


def rendered_selection(run: Run, selected: np.ndarray, view: View, backend: str | Backend = "cpu") -> np.ndarray:
    """(H, W) bool: where the ``selected`` Gaussians win the blended weight (a two-label
    :func:`rendered_labels`)."""
    return rendered_labels(run, selected.astype(np.uint8), view, backend) == 1


def clicks_alone(run: Run, regions: RegionWeights) -> ClickSelector:
    """The click rule of ``run`` with nothing from the masks: each view of the first mask layer
    of ``regions`` one region, every Gaussian one label, and object features of zero (they were
    learned from the masks)."""
    weights = regions.view_weights()
    views = np.flatnonzero(weights.getnnz(axis=1))
    one = RegionWeights(
        weights[views].astype(np.float32),
        views.astype(np.int32),
        np.ones(len(views), np.uint8),
        np.zeros(len(views), np.uint8),
        regions.layers[:1],
        regions.model,
    )
    blank = replace(run.gaussians, obj_feat=torch.zeros_like(run.gaussians.obj_feat))
    return ClickSelector(blank, np.ones(len(blank), np.uint8), one)


def masked_selector(run: Run, masks: dict[str, np.ndarray], labels: np.ndarray, layer: str) -> ClickSelector:
    """The click rule of ``run`` with other masks than its own: ``masks`` (H, W) bool of the
    training views by name (one region besides the background), ``labels`` (N,) and object
    features of zero (they were learned from the run's masks)."""
    train = [v for v in run.scene().split("train") if v.name in masks]
    masked = [MaskedView(v.camera, v.cam_from_world, masks[v.name].astype(np.uint8)) for v in train]
    regions = contribution_matrix(run.gaussians, masked, backend="cpu", regions=True, progress=False).regions
    regions.layers, regions.model = (layer,), run.fingerprint
    blank = replace(run.gaussians, obj_feat=torch.zeros_like(run.gaussians.obj_feat))
    return ClickSelector(blank, labels.astype(np.uint8), regions)


def half_given_away(
    run: Run, views: list[View], truth: dict[str, np.ndarray], obj: TrueObject
) -> tuple[ClickSelector, np.ndarray]:
    """The click rule of ``run`` where every training view's masks hold one half of the object
    and give the other half to the background: the object's Gaussians (``obj``) split at the
    median of their centres along their longest axis, a view's mask the people's mask where
    the first half's Gaussians draw it, the first half's Gaussians labelled
    (:func:`masked_selector`); and (H, W) bool the first half's pixels in the first of
    ``views``, where the first click goes."""
    means = run.gaussians.means.numpy().astype(np.float64)
    held = means[obj.held]
    axis = np.linalg.svd(held - held.mean(0), full_matrices=False)[2][0]
    along = (means - held.mean(0)) @ axis
    kept = obj.held & (along <= np.median(along[obj.held]))
    halves = np.where(kept, 1, np.where(obj.held, 2, 0)).astype(np.uint8)

    def kept_pixels(view: View) -> np.ndarray:
        return (rendered_labels(run, halves, view) == 1) & truth[view.name]

    masks = {v.name: kept_pixels(v) for v in run.scene().split("train") if v.name in truth}
    return masked_selector(run, masks, kept, "half"), kept_pixels(views[0])


def joined_to_surroundings(
    run: Run, views: list[View], truth: dict[str, np.ndarray], obj: TrueObject
) -> tuple[ClickSelector, np.ndarray]:
    """The click rule of ``run`` where every training view's masks join the object to what
    lies around it (tools and the table under them as one region): the surroundings are the
    Gaussians off the object (``obj``) whose centres lie nearest to one of its own, as many as
    it has (at most half of the rest); a view's mask the people's mask and the pixels the
    surroundings win, the object and its surroundings labelled (:func:`masked_selector`); and
    (H, W) bool the people's mask of the first of ``views``, where the first click goes."""
    means = run.gaussians.means.numpy().astype(np.float64)
    gap = cKDTree(means[obj.held]).query(means)[0]
    off = np.flatnonzero(~obj.held)
    near = off[np.argsort(gap[off], kind="stable")[: min(int(obj.held.sum()), len(off) // 2)]]
    joined = obj.held.copy()
    joined[near] = True
    surroundings = (~obj.held & joined).astype(np.uint8)
    masks = {
        v.name: truth[v.name] | (rendered_labels(run, surroundings, v) == 1)
        for v in run.scene().split("train")
        if v.name in truth
    }
    return masked_selector(run, masks, joined, "joined"), truth[views[0].name]


class Clicker:
    """Selections of a segmented run by clicks in the first view, or also in a ``second`` one
    (the rule of ``gsseg edit --click``; with nothing from the masks where ``alone``,
    :func:`clicks_alone`; the ``selector`` given, where one is), scored in the others."""

    def __init__(
        self,
        run: Run,
        views: list[View],
        truth: dict[str, np.ndarray],
        backend: str | Backend = "cpu",
        alone: bool = False,
        second: View | None = None,
        selector: ClickSelector | None = None,
    ):
        self.run, self.first, self.truth = run, views[0], truth
        self.others = [v for v in views[1:] if v is not second]
        self.backend = get_backend(backend)
        if selector is None:
            regions = run_regions(run, backend=self.backend)
            selector = (
                clicks_alone(run, regions) if alone else ClickSelector(run.gaussians, run.labels().labels, regions)
            )
        self.selector = selector
        self.clicks: list[ClickEvidence] = []
        self.selected = np.zeros(len(run.gaussians), bool)

    def click(self, u: float, v: float, positive: bool, view: View | None = None) -> None:
        """Add a click at pixel (u, v) of ``view`` (the first view by default); a click on
        nothing opaque, or a negative one before any positive, is spent without changing the
        selection."""
        try:
            view = view or self.first
            seen = click_evidence(
                self.run.gaussians, view.camera, view.cam_from_world, u, v, positive, backend=self.backend
            )
            clicks = [*self.clicks, seen]
            self.selected = self.selector.cut(clicks, self.selected if self.clicks else None)
            self.clicks = clicks
        except InputError:
            pass

    def scores(self) -> tuple[float, float]:
        """mIoU and mAcc of the selection over the other views."""
        pairs = [
            binary_scores(rendered_selection(self.run, self.selected, v, self.backend), self.truth[v.name])
            for v in self.others
        ]
        return float(np.mean([p[0] for p in pairs])), float(np.mean([p[1] for p in pairs]))

    def next_click(
        self, tried: list[tuple[float, float]], view: View | None = None
    ) -> tuple[float, float, bool] | None:
        """The deepest pixel of the largest error region of ``view`` (the first view by
        default) that holds no earlier click there (``tried``): (u, v, positive), or None when
        there is none."""
        view = view or self.first
        shown = rendered_selection(self.run, self.selected, view, self.backend)
        truth = self.truth[view.name]
        regions = []
        for positive, error in ((True, truth & ~shown), (False, shown & ~truth)):
            ids, n = ndimage.label(error)
            regions += [(int((ids == k).sum()), positive, ids == k) for k in range(1, n + 1)]
        for _, positive, region in sorted(regions, key=lambda r: -r[0]):
            if not any(region[int(v), int(u)] for u, v in tried):
                return (*deepest_pixel(region), positive)
        return None


def farthest_view(views: list[View]) -> View:
    """The view of ``views[1:]`` whose optical axis turns farthest from the first view's."""
    axis = np.asarray(views[0].cam_from_world)[2, :3]
    return min(views[1:], key=lambda v: float(np.asarray(v.cam_from_world)[2, :3] @ axis))


def interactive(
    run: Run,
    views: list[View],
    truth: dict[str, np.ndarray],
    max_clicks: int = MAX_CLICKS,
    backend: str | Backend = "cpu",
    past_target: bool = False,
    alone: bool = False,
    alternate: bool = False,
    given: tuple[ClickSelector, np.ndarray] | None = None,
) -> dict:
    """The single-click scores and the clicks to reach :data:`TARGET` (NoC@90), up to
    ``max_clicks`` (all ``max_clicks`` where ``past_target``: how later clicks behave),
    rendered on ``backend``; with nothing from the masks where ``alone`` (:class:`Clicker`);
    with the click rule and first view's pixels of other masks where ``given``
    (:func:`half_given_away`, :func:`joined_to_surroundings`), the first click deep inside
    those pixels. Where ``alternate``, the clicks after the first go in turn to the
    :func:`farthest_view` and the first view, as a user turns the model in the viewer, and the
    views other than the two are scored."""
    second = farthest_view(views) if alternate else None
    selector, first = (None, truth[views[0].name]) if given is None else given
    clicker = Clicker(run, views, truth, backend, alone, second, selector)
    u, v = deepest_pixel(first)
    clicker.click(u, v, True)
    miou, macc = clicker.scores()
    curve, tried = [miou], {views[0].name: [(u, v)]}
    while (past_target or curve[-1] < TARGET) and len(curve) < max_clicks:
        view = second if second is not None and len(curve) % 2 else views[0]
        nxt = clicker.next_click(tried.setdefault(view.name, []), view)
        if nxt is None:
            break
        clicker.click(*nxt, view)
        tried[view.name].append(nxt[:2])
        curve.append(clicker.scores()[0])
    reached = [k + 1 for k, m in enumerate(curve) if m >= TARGET]
    return {
        "single_click_miou": miou,
        "single_click_macc": macc,
        "noc90": reached[0] if reached else None,
        "miou_by_clicks": curve,
        "largest_fall": max([0.0, *(a - b for a, b in zip(curve, curve[1:]))]),
        "clicks": {name: [[float(a), float(b)] for a, b in at] for name, at in tried.items()},
        **({"second_view": second.name} if second is not None else {}),
    }


@dataclass(frozen=True)
class TrueObject:
    """What the people's masks hold of a model: ``weight`` (N,) each Gaussian's blended weight
    inside the masks over the views, and ``held`` (N,) whether most of its weight falls there
    (the object's Gaussians)."""

    weight: np.ndarray
    held: np.ndarray

    @classmethod
    def of(cls, run: Run, views: list[View], truth: dict[str, np.ndarray]) -> TrueObject:
        masked = [MaskedView(v.camera, v.cam_from_world, truth[v.name].astype(np.uint8)) for v in views]
        weights = contribution_matrix(run.gaussians, masked, backend="cpu", progress=False).weights.numpy()
        if len(weights) < 2:
            return cls(np.zeros(len(run.gaussians)), np.zeros(len(run.gaussians), bool))
        return cls(weights[-1].astype(np.float64), weights[-1] > 0.5 * weights.sum(0))

    def ceiling(self, run: Run, views: list[View], truth: dict[str, np.ndarray]) -> float:
        """The mIoU over the other views of the object's Gaussians: what a selection of this
        model can reach at best (the model's own blur and floaters bound it)."""
        return float(
            np.mean([binary_scores(rendered_selection(run, self.held, v), truth[v.name])[0] for v in views[1:]])
        )

    def left(self, removed: np.ndarray) -> float:
        """The share of the object's weight (its Gaussians' weight inside the masks) that a
        removal of ``removed`` (N,) leaves in the scene: its ghost."""
        return float(self.weight[self.held & ~removed].sum() / max(self.weight[self.held].sum(), 1e-12))


def removal_left(run: Run, views: list[View], truth: dict[str, np.ndarray], obj: TrueObject) -> float:
    """What :meth:`TrueObject.left` the single click's removal leaves: the click's selection with
    the Gaussians that served it alone in the training views, as ``gsseg edit --op remove``
    takes them."""
    clicker = Clicker(run, views, truth)
    clicker.click(*deepest_pixel(truth[views[0].name]), True)
    removed = complete_selection(run.gaussians, clicker.selected, run.scene().split("train"), backend=clicker.backend)
    return obj.left(removed.mask)


def mask_scores(scene_dir: Path, images: str, masks: str, truth: dict[str, np.ndarray]) -> dict:
    """Per view of the mask folder ``masks``: the IoU of the best single mask ID, of the union of
    the IDs mostly inside the person's mask; and the share of views whose best ID is the
    commonest best ID."""
    scene = load_scene(scene_dir, images=images, masks=masks)
    best, union, winners = [], [], []
    for view in scene.views:
        if view.name not in truth or view.mask_path is None:
            continue
        ids, person = view.load_mask(), truth[view.name]
        present = [i for i in np.unique(ids) if i]
        ious = {i: binary_scores(ids == i, person)[0] for i in present}
        winner = max(ious, key=ious.get) if ious else 0
        best.append(ious.get(winner, 0.0))
        winners.append(int(winner))
        inside = [i for i in present if (person[ids == i]).mean() > 0.5]
        union.append(binary_scores(np.isin(ids, inside), person)[0])
    common = max(set(winners), key=winners.count) if winners else 0
    return {
        "best_id_iou": float(np.mean(best)),
        "union_iou": float(np.mean(union)),
        "consistency": winners.count(common) / max(len(winners), 1),
        "ids_that_win": len(set(winners)),
    }


def run_scene(
    name: str,
    real: Path,
    work: Path,
    iters: int | None,
    max_gaussians: int | None,
    seed: int = 0,
    demo: bool = False,
    past_target: bool = False,
) -> dict:
    """Every stage of one scene, with its wall time; finished stages in ``work`` are reused.
    ``demo``: train the iterations and cap ``gsseg demo`` chooses for the capture;
    ``past_target``: all :data:`MAX_CLICKS` clicks (:func:`interactive`)."""
    times, out = {}, work / name
    start = time.perf_counter()
    try:
        scene_dir = posed_scene(real / name / "photos", out / "scene")
    except InputError as refused:  # the capture cannot be posed: a row that says so
        return {"scene": name, "refused": str(refused), "sfm_s": time.perf_counter() - start}
    times["sfm_s"] = time.perf_counter() - start
    images = demo_images(scene_dir)
    if demo:
        plan = demo_training(scene_dir, images, DemoOptions(scene=scene_dir))
        iters, max_gaussians = plan.iters, plan.max_gaussians
    start = time.perf_counter()
    if not (scene_dir / MASKS).is_dir():
        build_masks(scene_dir, BuildConfig(proposer="graph", associate="tracks", out_masks=MASKS, images=images))
    times["masks_s"] = time.perf_counter() - start
    run_dir = out / "run"
    start = time.perf_counter()
    if not (run_dir / "gaussians.ply").is_file():
        cfg = TrainConfig(iters=iters, masks=MASKS, images=images, max_gaussians=max_gaussians, seed=seed)
        train(scene_dir, run_dir, cfg)
    times["train_s"] = time.perf_counter() - start
    start = time.perf_counter()
    if not (scene_dir / DEPTH_MASKS).is_dir():
        shutil.rmtree(out / "depth", ignore_errors=True)  # of an interrupted pass
        masks_at_depth_jumps(run_dir, scene_dir, images, DEPTH_MASKS, out / "depth", backend="cpu")
    times["depth_masks_s"] = time.perf_counter() - start
    truth = people_masks(scene_dir, images, real / name / "masks")
    segment_run(run_dir, scene_dir, masks=DEPTH_MASKS)
    run = load_run(run_dir)
    views = [v for v in run.scene().views if v.name in truth]
    default_options = interactive(run, views, truth, max_clicks=1)["single_click_miou"]
    start = time.perf_counter()
    segment_run(run_dir, scene_dir, options=DEMO_LABELS, masks=DEPTH_MASKS)
    times["segment_s"] = time.perf_counter() - start
    start = time.perf_counter()
    run = load_run(run_dir)
    clicks = interactive(run, views, truth, past_target=past_target)
    times["clicks_s"] = time.perf_counter() - start
    alone = interactive(run, views, truth, past_target=True, alone=True)
    obj = TrueObject.of(run, views, truth)
    half = interactive(run, views, truth, past_target=True, given=half_given_away(run, views, truth, obj))
    joined = interactive(run, views, truth, past_target=True, given=joined_to_surroundings(run, views, truth, obj))
    alternating = {}
    if len(views) > 2:  # a view to score besides the two clicked
        masked = interactive(run, views, truth, past_target=True, alternate=True)
        unmasked = interactive(run, views, truth, past_target=True, alone=True, alternate=True)
        alternating = {
            "second_view": masked["second_view"],
            "masks": {k: masked[k] for k in CURVE},
            "alone": {k: unmasked[k] for k in CURVE},
        }
    return {
        "scene": name,
        "images": images,
        "views": len(views),
        "registered": len(run.scene().views),
        "photos": len(list((real / name / "photos").iterdir())),
        "gaussians": len(run.gaussians),
        "iters": run.config.timing.iters,
        **clicks,
        "clicks_alone": {k: alone[k] for k in CURVE},
        "half_given_away": {k: half[k] for k in CURVE},
        "joined_to_surroundings": {k: joined[k] for k in CURVE},
        **({"alternating": alternating} if alternating else {}),
        "ceiling_miou": obj.ceiling(run, views, truth),
        "object_left": removal_left(run, views, truth, obj),
        "single_click_miou_default_options": default_options,
        "masks": mask_scores(scene_dir, images, MASKS, truth),
        "depth_masks": mask_scores(scene_dir, images, DEPTH_MASKS, truth),
        **times,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--real", type=Path, default=Path("../shared/data/real"))
    parser.add_argument("--scenes", default="statue,dtu_scan24")
    parser.add_argument("--work", type=Path, default=Path("/tmp/real_scenes"))
    parser.add_argument("--iters", type=int, default=None, help="Training iterations (default: the CPU schedule's).")
    parser.add_argument("--max-gaussians", type=int, default=None)
    parser.add_argument("--demo", action="store_true", help="Train what gsseg demo chooses for each capture.")
    parser.add_argument("--seed", type=int, default=0, help="Training seed (the run-to-run spread).")
    parser.add_argument(
        "--past-target",
        action="store_true",
        help=f"Click {MAX_CLICKS} times, past mIoU {TARGET}: how later clicks behave.",
    )
    parser.add_argument("--tag", default="", help="Suffix of the JSON file's name.")
    parser.add_argument("--out", default=None, help="JSON file (default: benchmarks/results/real_scenes.json).")
    args = parser.parse_args()
    record.refuse_out_inside(parser, "real_scenes", args.work, tag=args.tag, out=args.out)
    results = {"scenes": []}
    for name in args.scenes.split(","):
        scene = run_scene(
            name, args.real, args.work, args.iters, args.max_gaussians, args.seed, args.demo, args.past_target
        )
        results["scenes"].append(scene)
        print(json.dumps(results["scenes"][-1], indent=2))
    record.save("real_scenes", results, tag=args.tag, out=args.out)


def report(r: dict) -> tuple[str, str]:
    def noc(x: dict) -> str:
        return str(x["noc90"]) if x["noc90"] is not None else f">{MAX_CLICKS}"

    refused = [x for x in r["scenes"] if "refused" in x]
    posed = [x for x in r["scenes"] if "refused" not in x]
    worst = min(posed, key=lambda x: x["single_click_miou"])
    headline = f"worst: {worst['scene']}, one click {worst['single_click_miou']:.3f}; " + "; ".join(
        [f"{x['scene']}: one click mIoU {x['single_click_miou']:.3f}, NoC@90 {noc(x)}" for x in posed]
        + [f"{x['scene']}: not posed by sfm" for x in refused]
    )
    falls = [x for x in posed if "largest_fall" in x and len(x["miou_by_clicks"]) > 1]
    if falls:
        steep = max(falls, key=lambda x: x["largest_fall"])
        headline += f"; largest fall after a click: {steep['largest_fall']:.3f} ({steep['scene']})"
    if any("clicks_alone" in x for x in posed):
        headline += "; the clicks alone, mIoU after the 10th: " + ", ".join(
            f"{x['scene']} {x['clicks_alone']['miou_by_clicks'][-1]:.3f}" for x in posed if "clicks_alone" in x
        )

    for key, title in (
        ("half_given_away", "half the object given away"),
        ("joined_to_surroundings", "joined to its surroundings"),
    ):
        if any(key in x for x in posed):
            headline += f"; {title}, mIoU after the 1st / 10th click, largest fall: " + ", ".join(
                f"{x['scene']} {x[key]['miou_by_clicks'][0]:.3f} / {x[key]['miou_by_clicks'][-1]:.3f}, "
                f"{x[key]['largest_fall']:.3f}"
                for x in posed
                if key in x
            )
    if any("alternating" in x for x in posed):
        headline += "; clicks alternating with a second view, NoC@90 with the masks / alone: " + ", ".join(
            f"{x['scene']} {noc(x['alternating']['masks'])} / {noc(x['alternating']['alone'])}"
            for x in posed
            if "alternating" in x
        )

    def curve_text(miou: list[float]) -> str:
        return " ".join(f"{m:.2f}" for m in miou)

    def masks(m: dict) -> str:
        return f"{m['best_id_iou']:.2f} / {m['union_iou']:.2f} / {m['consistency']:.2f}"

    def protocol(x: dict, key: str) -> str:
        if key not in x:
            return "n/a"
        a = x[key]
        return f"{curve_text(a['miou_by_clicks'])}; NoC@90 {noc(a)}; fall {a['largest_fall']:.3f}"

    def alternating(x: dict) -> str:
        if "alternating" not in x:
            return "n/a"
        a = x["alternating"]
        return f"{a['second_view']}: " + "; ".join(
            f"{kind}: {curve_text(a[kind]['miou_by_clicks'])}, fall {a[kind]['largest_fall']:.3f}"
            for kind in ("masks", "alone")
        )

    stages = ("sfm_s", "masks_s", "train_s", "depth_masks_s", "segment_s", "clicks_s")
    rows = [
        [
            x["scene"],
            f"{x['registered']}/{x['photos']}",
            x["images"],
            str(x["iters"]),
            f"{x['gaussians']:,}",
            f"{x['single_click_miou']:.3f}",
            f"{x['single_click_macc']:.3f}",
            f"{x['single_click_miou_default_options']:.3f}",
            f"{x['ceiling_miou']:.3f}" if "ceiling_miou" in x else "n/a",
            f"{x['object_left']:.1%}" if "object_left" in x else "n/a",
            noc(x),
            curve_text(x["miou_by_clicks"]),
            f"{x['largest_fall']:.3f}" if "largest_fall" in x else "n/a",
            protocol(x, "clicks_alone"),
            protocol(x, "half_given_away"),
            protocol(x, "joined_to_surroundings"),
            alternating(x),
            masks(x["masks"]),
            masks(x["depth_masks"]),
            " / ".join(f"{x[k]:.0f}" for k in stages),
        ]
        for x in posed
    ]
    table = markdown_table(
        [
            "scene",
            "registered",
            "images",
            "iterations",
            "Gaussians",
            "mIoU, 1 click",
            "mAcc, 1 click",
            "mIoU, 1 click, segment defaults",
            "ceiling: the people's masks' Gaussians",
            "object left by its removal",
            "NoC@90",
            "mIoU after each click",
            "largest fall after a click",
            "the clicks alone (masks that say nothing): mIoU after each click; NoC@90; largest fall",
            "half the object given away to the background: the same",
            "the object joined to its surroundings: the same",
            "clicks alternating with a second view: with the masks; alone",
            "masks of colour: best ID / union / consistency",
            "masks at depth jumps: the same",
            "seconds: sfm / masks / train / depth masks / segment / clicks",
        ],
        rows,
    )
    not_posed = "".join(f"\n\n{x['scene']}: not posed: {x['refused']}" for x in refused)
    return headline, (
        "People's masks of the real captures (docs/evaluation.md has the protocols); the first view "
        "is clicked, the others scored, with `--smooth 16 --fill-interiors` on the masks cut at the "
        "run's depth jumps (the demo's path) and with `gsseg segment`'s defaults. A stage reused from "
        "an earlier run shows about 0 s.\n\n" + table + not_posed
    )


if __name__ == "__main__":
    main()
