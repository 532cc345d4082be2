"""Ground truth for edits of a synthetic scene: for an object k and a view, the view with k
removed and k alone on white, ray-cast with the scene's own cameras.

The generator's light has no shadows and no interreflections, so removing an object changes
nothing but the pixels it covered: the view without k is the scene rendered without k. What
a removal can recover there depends on whether the training views saw it: ``seen`` marks the
pixels of k's visible region whose surface behind k some training view observes (the
learned environment stands in for the sky, which counts as seen). What an extraction can
recover depends on the same: ``silhouette_seen`` marks the pixels of k's whole silhouette
whose surface of k some training view observes (a forward capture never sees the parts of an
object that other objects hide from every view).

The layout comes back from the ``scene.json`` the generator writes (its options and seed).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from tqdm import tqdm

from dataset_tools.image_files import read_image, read_mask, write_png
from dataset_tools.infra.atomic import atomic_directory
from dataset_tools.infra.errors import InputError, OptionError, OutputExists
from dataset_tools.scene import IMAGES, View, load_scene
from dataset_tools.synth.generator import Layout, SynthConfig, make_layout, observe, render_view

WHITE = (1.0, 1.0, 1.0)
EDIT_TRUTH = "edit_truth"


@dataclass
class EditTruth:
    """One object in one view.

    Attributes:
        without: (H, W, 3) uint8, the view with the object removed.
        alone: (H, W, 3) uint8, the object alone on white.
        silhouette: (H, W) bool, its whole silhouette (the parts other objects hide included).
        seen: (H, W) bool, the pixels it covers in the view whose background a training view sees.
        silhouette_seen: (H, W) bool, the silhouette pixels whose surface of the object a
            training view sees.
    """

    without: np.ndarray
    alone: np.ndarray
    silhouette: np.ndarray
    seen: np.ndarray
    silhouette_seen: np.ndarray


def scene_config(scene_dir: Path) -> SynthConfig:
    """The options a synthetic scene folder was made with, from its scene.json."""
    meta_path = Path(scene_dir) / "scene.json"
    try:
        return SynthConfig(**json.loads(meta_path.read_text())["provenance"]["config"])
    except (OSError, ValueError, KeyError) as e:
        raise InputError(
            f"{meta_path}: not a synthetic scene of `python -m dataset_tools synth` ({e}); "
            "edit ground truth exists for synthetic scenes only."
        ) from None


def scene_layout(scene_dir: Path) -> Layout:
    """The layout of a synthetic scene folder, rebuilt from the options in its scene.json."""
    cfg = scene_config(scene_dir)
    return make_layout(cfg, np.random.default_rng(cfg.seed))


def _without(layout: Layout, object_id: int) -> Layout:
    return replace(layout, objects=[o for o in layout.objects if o.id != object_id])


def _alone(layout: Layout, object_id: int) -> Layout:
    return replace(layout, objects=[o for o in layout.objects if o.id == object_id], background=[])


def edit_truth(
    layout: Layout,
    object_id: int,
    view: View,
    seers: list[tuple[View, np.ndarray]],
    supersample: int = SynthConfig.supersample,
) -> EditTruth:
    """The truth of editing ``object_id`` in ``view``.

    Args:
        seers: the training views with their depth (H, W) in the full scene, which decide ``seen``.
    """
    if not any(o.id == object_id for o in layout.objects):
        raise InputError(f"object {object_id} is not in this scene; pick one of {[o.id for o in layout.objects]}.")
    cam, pose = view.camera, view.cam_from_world
    without, _, depth_behind, behind = render_view(_without(layout, object_id), cam, pose, supersample)
    alone, ids, _, surface = render_view(_alone(layout, object_id), cam, pose, supersample, sky=WHITE)
    _, full_ids, _, _ = render_view(layout, cam, pose, 1)
    covered = (full_ids == object_id).ravel()
    seen = _seen_by(behind, covered, seers) | (covered & ~np.isfinite(depth_behind.ravel()))  # sky: the environment
    silhouette = ids == object_id
    H, W = full_ids.shape
    return EditTruth(
        without, alone, silhouette, seen.reshape(H, W), _seen_by(surface, silhouette.ravel(), seers).reshape(H, W)
    )


def _seen_by(points: np.ndarray, pixels: np.ndarray, seers: list[tuple[View, np.ndarray]]) -> np.ndarray:
    """(H*W,) bool: which of the ``pixels`` (H*W,) bool have their (H*W, 3) surface ``points``
    observed (in view, not occluded) by one of the ``seers``; False elsewhere."""
    out = np.zeros(len(pixels), bool)
    rows = np.flatnonzero(pixels)
    for other, depth in seers:
        found, _ = observe(points[rows], other.camera, other.cam_from_world, depth)
        out[rows[found]] = True
    return out


def write_edit_truth(
    scene_dir: Path | str,
    *,
    images: str = IMAGES,
    split: str = "test",
    overwrite: bool = False,
    progress: bool = True,
) -> Path:
    """Write ``scene_dir/edit_truth/<k>/<item>/<stem>.png``, each item of :class:`EditTruth`,
    for every object k and every view of ``split``, at the size of the ``images`` copy (an ``images_N``
    copy is the full views area-averaged, so its truth takes N times the generator's samples
    a side); the folder appears whole or not at all."""
    scene_dir = Path(scene_dir)
    cfg = scene_config(scene_dir)
    layout = make_layout(cfg, np.random.default_rng(cfg.seed))
    scene = load_scene(scene_dir, images=images, masks=None)
    factor = int(images.rsplit("_", 1)[1]) if "_" in images else 1
    supersample = cfg.supersample * factor
    out = scene_dir / EDIT_TRUTH
    if out.exists() and not overwrite:
        raise OutputExists(out)
    seers = [(v, render_view(layout, v.camera, v.cam_from_world, 1)[2]) for v in scene.split("train")]
    with atomic_directory(out, overwrite=overwrite) as tmp:
        for obj in tqdm(layout.objects, desc="edit truth", unit="object", disable=not progress):
            for view in scene.split(split):
                truth = edit_truth(layout, obj.id, view, seers, supersample)
                base = tmp / str(obj.id)
                write_png(base / "without" / f"{view.stem}.png", truth.without)
                write_png(base / "alone" / f"{view.stem}.png", truth.alone)
                write_png(base / "silhouette" / f"{view.stem}.png", truth.silhouette.astype(np.uint8) * 255)
                write_png(base / "seen" / f"{view.stem}.png", truth.seen.astype(np.uint8) * 255)
                write_png(base / "silhouette_seen" / f"{view.stem}.png", truth.silhouette_seen.astype(np.uint8) * 255)
    return out


def read_edit_truth(scene_dir: Path | str, object_id: int, stem: str) -> EditTruth | None:
    """The truth ``write_edit_truth`` wrote for one object and view, or None where there is none."""
    base = Path(scene_dir) / EDIT_TRUTH / str(object_id)
    if not (base / "without" / f"{stem}.png").is_file():
        return None
    if not (base / "silhouette_seen" / f"{stem}.png").is_file():
        raise OptionError(
            "written by an older version (no silhouette_seen/); write it again with {overwrite}.",
            file=base.parent,
            overwrite=True,
        )
    return EditTruth(
        read_image(base / "without" / f"{stem}.png"),
        read_image(base / "alone" / f"{stem}.png"),
        *(read_mask(base / name / f"{stem}.png") > 0 for name in ("silhouette", "seen", "silhouette_seen")),
    )
