"""``hqmask build`` and ``hqmask clean``: proposals -> noise removal -> association ->
multi-view consensus -> noise removal -> ID maps.

Proposals of the expensive proposers are cached per view under
``SCENE/.hqmask_cache/<cache name>/`` (the proposer and, for ``sam-hq``, the model and
grid; for ``graph`` with ``--depth``, a digest of the depth maps) so an interrupted run
resumes where it stopped; the
output mask folder appears whole, atomically, at the end.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from pathlib import Path

import cv2
import numpy as np
from tqdm import tqdm

from dataset_tools.depth_maps import read_depth
from dataset_tools.image_files import encode_png, read_mask
from dataset_tools.infra.atomic import atomic_directory, write_bytes_atomic
from dataset_tools.infra.checked_files import read_checked, write_checked
from dataset_tools.infra.engine import Engine, task_cpus
from dataset_tools.infra.errors import InputError, OptionError, OutputExists
from dataset_tools.infra.locks import exclusive_folder
from dataset_tools.infra.names import plain_name
from dataset_tools.infra.overlap import refuse_overlap, scene_entries, scene_inputs
from dataset_tools.mask_manifest import MANIFEST, manifest_bytes, refuse_truth
from dataset_tools.scene import Scene, View, load_scene, mask_folder
from hqmask.association import associate_flow, associate_tracks
from hqmask.association.anchors import sighting, triangulate
from hqmask.build_options import BuildConfig, check_min_area
from hqmask.cleanup import clean_mask
from hqmask.consensus import multiview_consensus
from hqmask.depth_prior import depth_from_anchors, depth_from_points
from hqmask.proposers.base import Proposer
from hqmask.proposers.registry import make_proposer
from hqmask.support_plane import Heights, SupportPlane, support_plane

CACHE = ".hqmask_cache"


@dataclass
class BuildResult:
    out_dir: Path
    n_objects: int
    views: int
    associate: str  # the association used (``auto`` resolved)


def association_for(scene: Scene, associate: str) -> str:
    """``auto`` -> ``tracks`` where the views observe SfM points, else ``flow``."""
    if associate != "auto":
        return associate
    return "tracks" if len(scene.points) and any(len(v.point_ids) for v in scene.views) else "flow"


def propose_view(
    proposer: Proposer, job: tuple[np.ndarray, View, Path | None, np.ndarray | None, np.ndarray | None]
) -> np.ndarray:
    """The painted proposals of one (image, view, cache file or None, depth map or None, height
    map or None) as an (H, W) uint8 segment map, written to the cache file when there is one."""
    image, view, cached, depth, height = job
    seg = proposer.propose(image, view, depth, height).paint()
    if seg.max() > 255:
        raise OptionError(
            f"the proposer made {seg.max()} segments, more than 255; raise {{min_area}}.", file=view.image_path
        )
    seg = seg.astype(np.uint8)
    if cached is not None:
        write_checked(cached, encode_png(seg))
    return seg


def read_cached_segments(path: Path | None) -> np.ndarray | None:
    """The segment map cached at ``path``, or None when there is none or it is damaged."""
    data = read_checked(path) if path is not None else None
    seg = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED) if data else None
    return seg if seg is not None and seg.ndim == 2 and seg.dtype == np.uint8 else None


@dataclass
class SceneGeometry:
    """What the mask stage knows of the scene's geometry from a trained run: every view's
    ``depths`` (H, W), the plane the scene stands on (None where none is found) with every
    view's ``heights`` above it (None without a plane), and a ``digest`` of them all that names
    the proposals made with them in the cache."""

    depths: list[np.ndarray]
    plane: SupportPlane | None
    heights: list[Heights] | None
    digest: str


def read_geometry(scene: Scene, folder: Path) -> SceneGeometry:
    """Every view's depth map from ``folder/<stem>.npy`` (checked against the view's size), and
    the support plane of the scene's SfM points with the heights above it."""
    if not folder.is_dir():
        raise OptionError(
            "depth folder not found; write it with `gsseg render RUN --what depth "
            "--split all --out DIR` and pass DIR/depth as {depth}.",
            file=folder,
        )
    depths = [read_depth(folder / f"{view.stem}.npy", (view.camera.width, view.camera.height)) for view in scene.views]
    plane = support_plane(scene.points.xyz, np.array([view.cam_from_world for view in scene.views]))
    heights = None if plane is None else [plane.heights(v, d) for v, d in zip(scene.views, depths)]
    digest = hashlib.blake2b(digest_size=8)
    for depth in depths:
        digest.update(depth.tobytes())
    if plane is not None:
        digest.update(
            np.array(
                [*plane.normal, plane.offset, plane.scale, *plane.centre, plane.reach, plane.under_focus]
            ).tobytes()
        )
    return SceneGeometry(depths, plane, heights, digest.hexdigest())


def _segments(
    scene: Scene,
    proposer: Proposer,
    make: Callable[[], Proposer],
    cfg: BuildConfig,
    images: list[np.ndarray],
    geometry: SceneGeometry | None,
    engine: Engine,
    progress: bool,
) -> list[np.ndarray]:
    """Per view, the painted proposals as an (H, W) uint8 segment map, cleaned: read from the
    cache, or proposed on ``engine`` (where each Ray worker makes its proposer once with
    ``make``) and cached view by view, so that an interrupted build resumes."""
    none = [None] * len(scene.views)
    depths, heights = (none, none) if geometry is None else (geometry.depths, geometry.heights or none)
    name = proposer.cache_name
    if geometry is not None and name is not None:
        name = f"{name}-depth-{geometry.digest}"
    cache = None if name is None else scene.root / CACHE / name
    paths = [None if cache is None else cache / f"{view.stem}.png" for view in scene.views]
    segments = {
        k: seg for k, path in enumerate(paths) if not cfg.force and (seg := read_cached_segments(path)) is not None
    }
    todo = [k for k in range(len(paths)) if k not in segments]
    fresh = engine.map_stateful(
        make,
        propose_view,
        [(images[k], scene.views[k], paths[k], depths[k], heights[k]) for k in todo],
        local_state=proposer,
        threads=task_cpus() if proposer.threadable else 1,
        desc=f"proposing ({cfg.proposer})",
        progress=progress,
    )
    segments.update(zip(todo, fresh))
    return [clean_mask(segments[k], cfg.min_area) for k in range(len(paths))]


def depth_priors(scene: Scene, ids: list[np.ndarray], associate: str) -> list[np.ndarray | None]:
    """A rough depth of every view to start the consensus' flow from: from the SfM points
    each view observes (``tracks``), or from where the associated objects stand (``flow``)."""
    if associate == "tracks":
        return [depth_from_points(v, v.uv, scene.points.xyz[v.point_ids], m) for v, m in zip(scene.views, ids)]
    sightings: dict[int, list] = {}
    for k, (v, m) in enumerate(zip(scene.views, ids)):
        for label in np.unique(m[m > 0]):
            sightings.setdefault(int(label), []).append(sighting(k, m == label, v.camera, v.cam_from_world))
    anchors = {label: a for label, s in sightings.items() if (a := triangulate(s)) is not None}
    return [depth_from_anchors(v, m, anchors) for v, m in zip(scene.views, ids)]


def build_scene(job: tuple[Path, BuildConfig]) -> BuildResult:
    """:func:`build_masks` of one (scene, options) pair without progress bars: a task for
    :meth:`dataset_tools.infra.engine.Engine.map` over several scenes."""
    return build_masks(job[0], job[1], progress=False)


def build_masks(
    scene_dir: Path | str, cfg: BuildConfig, *, engine: Engine = Engine(), progress: bool = True
) -> BuildResult:
    """Write consistent, cleaned object-ID maps of every view to ``scene_dir/cfg.out_masks``;
    the views' proposals are made on ``engine``."""
    scene_dir = Path(scene_dir)
    out_dir = scene_dir / cfg.out_masks
    reads = scene_inputs(scene_dir, [cfg.from_masks and mask_folder(scene_dir, cfg.from_masks)])
    if cfg.depth is not None:
        reads.append(("the depth maps", Path(cfg.depth)))
    refuse_overlap(out_dir, reads)
    if cfg.dataset:  # a dataset is no part of the scene: it may replace nothing in it
        refuse_overlap(cfg.dataset, [*scene_entries(scene_dir), ("the mask folder it writes", out_dir)])
    make = partial(make_proposer, cfg, scene_dir / CACHE / "sam-hq-embeddings" if cfg.cache_embeddings else None)
    proposer = make()  # an unknown or unavailable one fails before any work
    refuse_truth(out_dir, "force")
    if out_dir.exists() and not cfg.force:
        raise OutputExists(out_dir, option="force")
    if cfg.dataset and Path(cfg.dataset).exists() and not cfg.force:
        raise OutputExists(cfg.dataset, " or choose another {dataset}", option="force")
    if not scene_dir.is_dir():
        raise InputError(f"{scene_dir}: scene folder not found; check the path.")
    with exclusive_folder(scene_dir, "masks"):
        return _build_locked(scene_dir, out_dir, cfg, proposer, make, engine, progress)


def _build_locked(
    scene_dir: Path,
    out_dir: Path,
    cfg: BuildConfig,
    proposer: Proposer,
    make: Callable[[], Proposer],
    engine: Engine,
    progress: bool,
) -> BuildResult:
    scene = load_scene(scene_dir, images=cfg.images, masks=cfg.from_masks if cfg.proposer == "existing" else None)
    if cfg.proposer == "existing" and scene.mask_dir is None:
        raise OptionError("mask folder not found; check {from_masks}.", file=scene_dir / cfg.from_masks)
    images = [v.load_image() for v in tqdm(scene.views, desc="loading images", disable=not progress)]
    geometry = read_geometry(scene, Path(cfg.depth)) if cfg.depth is not None else None
    segments = [s.astype(np.int32) for s in _segments(scene, proposer, make, cfg, images, geometry, engine, progress)]
    associate = association_for(scene, cfg.associate)
    if associate == "flow":
        ids = associate_flow(images, segments, scene.views)
    else:
        ids = associate_tracks(scene.views, segments, len(scene.points))
    if cfg.consensus:
        ids = multiview_consensus(
            images,
            ids,
            scene.views,
            depths=depth_priors(scene, ids, associate),
            neighbours=cfg.consensus,
            progress=progress,
        )
    n_objects = 0
    with atomic_directory(out_dir, overwrite=cfg.force) as tmp:
        for view, m in zip(tqdm(scene.views, desc="writing masks", disable=not progress), ids):
            m = clean_mask(m, cfg.min_area)
            n_objects = max(n_objects, int(m.max()))
            write_bytes_atomic(tmp / f"{view.stem}.png", encode_png(view.to_file_frame(m)))
        write_bytes_atomic(tmp / MANIFEST, _manifest(cfg, associate, geometry))
    if cfg.dataset:
        from dataset_tools.dataset_rows import export_dataset

        export_dataset(
            load_scene(scene_dir, images=cfg.images, masks=cfg.out_masks), Path(cfg.dataset), overwrite=cfg.force
        )
    return BuildResult(out_dir, n_objects, len(scene.views), associate)


def _manifest(cfg: BuildConfig, associate: str, geometry: SceneGeometry | None) -> bytes:
    """What shaped a built mask folder (:mod:`dataset_tools.mask_manifest`)."""
    sam = cfg.proposer == "sam-hq"
    return manifest_bytes(
        "hqmask build",
        proposer=cfg.proposer,
        from_masks=cfg.from_masks,
        model=cfg.model if sam else None,
        points_per_side=cfg.points_per_side if sam else None,
        associate=associate,
        consensus=cfg.consensus,
        min_area=cfg.min_area,
        images=cfg.images,
        depth=None if geometry is None else _geometry_record(cfg, geometry),
    )


def _geometry_record(cfg: BuildConfig, geometry: SceneGeometry) -> dict:
    plane = geometry.plane
    return {
        "folder": str(Path(cfg.depth).resolve()),
        "digest": geometry.digest,
        "support_plane": None
        if plane is None
        else {"normal": plane.normal.tolist(), "offset": plane.offset, "under_focus": plane.under_focus},
    }


def clean_scene_masks(
    scene_dir: Path | str,
    masks: str,
    out_masks: str,
    *,
    min_area: int | None = None,
    force: bool = False,
    progress: bool = True,
) -> Path:
    """Noise removal alone: ``scene_dir/masks`` -> ``scene_dir/out_masks``."""
    scene_dir = Path(scene_dir)
    src, dst = scene_dir / masks, scene_dir / plain_name(out_masks, "out_masks")
    check_min_area(min_area)
    if not src.is_dir():
        raise OptionError("mask folder not found; check {masks}.", file=src)
    refuse_overlap(dst, scene_inputs(scene_dir, [masks]))
    refuse_truth(dst, "force")
    if dst.exists() and not force:
        raise OutputExists(dst, option="force")
    files = sorted(src.rglob("*.png"))
    with exclusive_folder(scene_dir, "masks"), atomic_directory(dst, overwrite=force) as tmp:
        for f in tqdm(files, desc="cleaning", disable=not progress):
            target = tmp / f.relative_to(src)
            write_bytes_atomic(target, encode_png(clean_mask(read_mask(f), min_area)))
        write_bytes_atomic(tmp / MANIFEST, manifest_bytes("hqmask clean", from_masks=masks, min_area=min_area))
    return dst
