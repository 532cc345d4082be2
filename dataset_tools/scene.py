"""The scene folder, the format every stage reads and writes: loading, saving, splits and
lazy image access.

scene/
  images/ images_2/ ...   RGB images (jpg or png), optional downsampled copies
  sparse/0/               COLMAP model, binary or text
  object_mask/            one 8-bit PNG of object IDs a view, same stem as the image: the
                          masks that train (``hqmask build``'s, or another tool's)
  gt_mask/                a synthetic scene's exact masks, in the same format: for scores only
  scene.json              optional: object names, split, provenance

Every mask folder may say how it was made (:mod:`dataset_tools.mask_manifest`).
"""

from __future__ import annotations

import json
import shutil
import warnings
from dataclasses import dataclass, field, replace
from functools import cached_property
from pathlib import Path
from typing import Literal

import cv2
import numpy as np

from dataset_tools import colmap
from dataset_tools.cameras import DEFAULT_NEAR, PINHOLE_MODELS, PinholeCamera, SourceCamera
from dataset_tools.image_files import encode_image, encode_png, image_size, read_image, read_mask
from dataset_tools.infra.atomic import atomic_directory, write_bytes_atomic
from dataset_tools.infra.errors import InputError, OutputExists
from dataset_tools.mask_manifest import read_manifest

Split = Literal["train", "test", "all"]
IMAGES = "images"  # the photos; downsampled copies are images_<factor>
MASKS = "object_mask"  # the masks that train
GT_MASKS = "gt_mask"  # the exact masks of a synthetic scene


@dataclass
class SparsePoints:
    """The SfM points of a scene: xyz (P, 3) float64, rgb (P, 3) uint8."""

    xyz: np.ndarray
    rgb: np.ndarray

    def __len__(self) -> int:
        return len(self.xyz)


@dataclass
class View:
    """One posed view. Images and masks are read from disk only when asked for.

    Attributes:
        name: image file name inside the image folder, e.g. ``"0001.jpg"``.
        camera: pinhole camera of the loaded (undistorted) image.
        cam_from_world: (3, 4) float64 world-to-camera transform [R | t] (COLMAP convention:
            x right, y down, z forward).
        image_path: the image file. mask_path: its object-ID map, or None when there is none.
        point_ids: (M,) int64 rows of ``Scene.points`` observed in this view.
        uv: (M, 2) float64 pixel coordinates of those observations in the loaded image.
        source_camera: the distorted camera of the file, or None for pinhole files.
    """

    name: str
    camera: PinholeCamera
    cam_from_world: np.ndarray
    image_path: Path
    mask_path: Path | None
    point_ids: np.ndarray
    uv: np.ndarray
    source_camera: SourceCamera | None = None
    mask_full_size: tuple[int, int] | None = None

    @property
    def stem(self) -> str:
        """File name without suffix (may contain sub-folders); masks and renders use it."""
        return str(Path(self.name).with_suffix(""))

    @property
    def R(self) -> np.ndarray:
        return self.cam_from_world[:, :3]

    @property
    def t(self) -> np.ndarray:
        return self.cam_from_world[:, 3]

    @property
    def center(self) -> np.ndarray:
        """Camera centre in world coordinates, (3,)."""
        return -self.R.T @ self.t

    @cached_property
    def _maps(self) -> tuple[np.ndarray, np.ndarray]:
        return colmap.undistortion_maps(self.source_camera, self.camera)

    def to_file_frame(self, ids: np.ndarray) -> np.ndarray:
        """An (H, W) ID map of the loaded (undistorted) view resampled (nearest) into the frame
        of the image file, where masks are stored; unchanged for pinhole files."""
        if self.source_camera is None:
            return ids
        return colmap.remap(ids, colmap.distortion_maps(self.source_camera, self.camera), nearest=True)

    @property
    def file_size(self) -> tuple[int, int]:
        """(width, height) of the file on disk (before undistortion)."""
        src = self.source_camera
        return (src.width, src.height) if src else (self.camera.width, self.camera.height)

    def load_image(self) -> np.ndarray:
        """The undistorted RGB image, (H, W, 3) uint8 with H, W = camera.height, camera.width."""
        img = read_image(self.image_path)
        if (img.shape[1], img.shape[0]) != self.file_size:
            raise InputError(
                f"{self.image_path}: image is {img.shape[1]}x{img.shape[0]} but its header said "
                f"{self.file_size[0]}x{self.file_size[1]}; re-save the file."
            )
        return colmap.remap(img, self._maps, nearest=False) if self.source_camera else img

    def load_mask(self) -> np.ndarray | None:
        """The undistorted object-ID map, (H, W) uint8, or None if the view has no mask.

        A mask must be the size of the image file; a mask at the size of the full-resolution
        ``images/`` file is also accepted and resized (nearest) to the loaded image.
        """
        if self.mask_path is None:
            return None
        ids = read_mask(self.mask_path)
        size = (ids.shape[1], ids.shape[0])
        if size != self.file_size:
            if size != self.mask_full_size:
                raise InputError(
                    f"{self.mask_path}: mask is {size[0]}x{size[1]} but its image is "
                    f"{self.file_size[0]}x{self.file_size[1]}; masks must have the size of their image."
                )
            ids = cv2.resize(ids, self.file_size, interpolation=cv2.INTER_NEAREST_EXACT)
        return colmap.remap(ids, self._maps, nearest=True) if self.source_camera else ids


@dataclass
class Scene:
    """A loaded scene folder. Views are sorted by image name."""

    root: Path
    views: list[View]
    points: SparsePoints
    image_dir: str = IMAGES
    mask_dir: str | None = MASKS
    test_names: frozenset[str] = frozenset()
    meta: dict = field(default_factory=dict)

    def split(self, which: Split = "all") -> list[View]:
        """The views of a split: ``train``, ``test`` or ``all``."""
        if which == "all":
            return list(self.views)
        if which not in ("train", "test"):
            raise InputError(f"unknown split {which!r}; use train, test or all.")
        test = which == "test"
        return [v for v in self.views if (v.name in self.test_names) == test]

    def view(self, name_or_stem: str) -> View:
        """The view with this image name or stem."""
        for v in self.views:
            if name_or_stem in (v.name, v.stem):
                return v
        raise InputError(f"{self.root}: no view named {name_or_stem!r}; see `python -m dataset_tools inspect`.")

    @property
    def has_masks(self) -> bool:
        return any(v.mask_path is not None for v in self.views)


def llff_test_names(names: list[str], every: int = 8) -> frozenset[str]:
    """LLFF hold-out: every ``every``-th view of the name-sorted list (starting at 0) is a test view."""
    if every <= 0:
        return frozenset()
    return frozenset(n for k, n in enumerate(sorted(names)) if k % every == 0)


def scene_near_plane(images: list[colmap.ColmapImage], xyz: np.ndarray, fraction: float = 0.5) -> float:
    """The near plane of a scene's cameras: ``fraction`` of the smallest depth at which a view
    observes SfM points (each view's 1st percentile, so that a stray point does not decide),
    as LLFF derives NeRF's near bound from the same depths; 3D-GS's 0.2 when no view
    observes a point.

    Nothing the SfM reconstruction saw lies nearer. What 3D-GS grows there is a floater: on
    a 360-degree capture, Gaussians just in front of a held-out camera, outside the fields of
    view of the training cameras beside it, model far background for the opposite views and
    veil the held-out view.

    Args:
        images: the COLMAP images, with (3, 4) ``cam_from_world`` and observed ``point_ids``.
        xyz: (P, 3) SfM points.
    """
    nearest = []
    for im in images:
        if len(im.point_ids):
            depth = xyz[im.point_ids] @ im.cam_from_world[2, :3] + im.cam_from_world[2, 3]
            depth = depth[depth > 0]
            if len(depth):
                nearest.append(np.percentile(depth, 1.0))
    return fraction * float(min(nearest)) if nearest else DEFAULT_NEAR


def mask_folder(root: Path | str, masks: str) -> str:
    """The name of the mask folder ``masks`` of the scene ``root``. A synthetic scene made
    before ground truth had a folder of its own keeps it in ``object_mask/``, marked as ground
    truth by its manifest: asked for ``gt_mask``, such a scene answers ``object_mask``, with a
    note."""
    root = Path(root)
    if masks != GT_MASKS or (root / GT_MASKS).is_dir():
        return masks
    if (read_manifest(root / MASKS) or {}).get("truth"):
        warnings.warn(
            f"{root}: a synthetic scene from before gt_mask/; its ground truth is read from {MASKS}/ "
            f"(make the scene again, or rename the folder to {GT_MASKS}/, to silence this note).",
            stacklevel=2,
        )
        return MASKS
    return masks


def read_scene_json(root: Path) -> dict:
    path = Path(root) / "scene.json"
    if not path.exists():
        return {}
    try:
        meta = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise InputError(f"{path}: not valid JSON ({e}); fix or delete the file.") from None
    if not isinstance(meta, dict):
        raise InputError(f"{path}: must hold a JSON object; fix or delete the file.")
    return meta


def load_scene(
    root: Path | str,
    *,
    images: str = IMAGES,
    masks: str | None = MASKS,
    test_every: int = 8,
) -> Scene:
    """Load a scene folder.

    Args:
        root: the scene folder.
        images: image folder to read (``images`` or a downsampled ``images_N``).
        masks: object-ID map folder, or None to ignore masks. A missing folder, or a view
            without a mask file, means no supervision for that view, not an error.
            ``gt_mask`` in a scene made before that name reads its ground truth from
            ``object_mask`` (:func:`mask_folder`).
        test_every: LLFF hold-out period, used unless scene.json lists ``split.test``.

    Non-pinhole COLMAP cameras are undistorted on load into pinhole cameras (COLMAP's
    undistorted camera, OpenCV remapping); observations are moved accordingly. Every camera
    gets the scene's near plane (:func:`scene_near_plane`).
    """
    root = Path(root)
    if not root.is_dir():
        raise InputError(f"{root}: scene folder not found; check the path.")
    image_root = root / images
    if not image_root.is_dir():
        raise InputError(
            f"{image_root}: image folder not found; put the views in {images}/ or pick another image folder."
        )
    model = colmap.read_model(root / "sparse" / "0")
    masks = mask_folder(root, masks) if masks else None
    mask_root = root / masks if masks else None
    near = scene_near_plane(model.images, model.xyz)
    views = [_pinhole_view(im, image_root, mask_root, near) for im in model.images]
    meta = read_scene_json(root)
    return Scene(
        root=root,
        views=views,
        points=SparsePoints(model.xyz, model.rgb),
        image_dir=images,
        mask_dir=masks if mask_root is not None and mask_root.is_dir() else None,
        test_names=_test_names(root, meta, [v.name for v in views], test_every),
        meta=meta,
    )


def _pinhole_view(im: colmap.ColmapImage, image_root: Path, mask_root: Path | None, near: float) -> View:
    """The view of COLMAP image ``im`` at the size of its file in ``image_root``: a pinhole
    camera with near plane ``near``, the observations undistorted with it when ``im``'s camera
    is not pinhole, and its mask in ``mask_root`` when the file is there."""
    path = image_root / im.name
    if not path.is_file():
        raise InputError(
            f"{path}: image listed in the COLMAP model is missing on disk; restore it or "
            "remove the image from sparse/0."
        )
    width, height = image_size(path)
    src = colmap.resize_source_camera(im.camera, width, height)
    aspect_in, aspect_cam = width / height, im.camera.width / im.camera.height
    if abs(aspect_in - aspect_cam) > 0.02 * aspect_cam:
        raise InputError(
            f"{path}: image is {width}x{height} but its COLMAP camera is "
            f"{im.camera.width}x{im.camera.height}; the image folder does not match the model."
        )
    camera = replace(colmap.pinhole_camera(src), near=near)
    uv = im.uv * [width / im.camera.width, height / im.camera.height]
    distorted = src.model not in PINHOLE_MODELS
    if distorted:
        uv = colmap.undistort_points(uv, src, camera)
    mask_path = (mask_root / f"{Path(im.name).with_suffix('')}.png") if mask_root else None
    return View(
        name=im.name,
        camera=camera,
        cam_from_world=im.cam_from_world,
        image_path=path,
        mask_path=mask_path if mask_path is not None and mask_path.is_file() else None,
        point_ids=im.point_ids,
        uv=uv,
        source_camera=src if distorted else None,
        mask_full_size=(im.camera.width, im.camera.height),
    )


def _test_names(root: Path, meta: dict, names: list[str], test_every: int) -> frozenset[str]:
    """The held-out views: scene.json's ``split.test`` when it lists them, else every
    ``test_every``-th of ``names`` (LLFF's hold-out)."""
    split = meta.get("split", {})
    listed = split.get("test") if isinstance(split, dict) else split
    if listed is not None and not (isinstance(listed, list) and all(isinstance(n, str) for n in listed)):
        raise InputError(
            f"{root / 'scene.json'}: split.test is {type(listed).__name__}, not a list of view names; write it as "
            '{"split": {"test": ["name.png", ...]}}.'
        )
    test_names = frozenset(listed) if listed is not None else llff_test_names(names, test_every)
    unknown = test_names - set(names)
    if unknown:
        raise InputError(
            f"{root / 'scene.json'}: split.test names views that do not exist ({sorted(unknown)[:3]}); fix the list."
        )
    return test_names


def save_scene(scene: Scene, out: Path | str, *, overwrite: bool = False, text: bool = False) -> Path:
    """Write a scene as a complete scene folder of pinhole cameras at the loaded resolution.

    Files already pinhole are copied byte for byte; undistorted views are re-encoded with
    their own suffix; the loaded masks keep their folder's name. The folder appears whole or
    not at all.
    """
    out = Path(out)
    if out.exists() and not overwrite:
        raise OutputExists(out)
    with atomic_directory(out, overwrite=overwrite) as tmp:
        for v in scene.views:
            dst = tmp / "images" / v.name
            dst.parent.mkdir(parents=True, exist_ok=True)
            if v.source_camera is None:
                shutil.copyfile(v.image_path, dst)
            else:
                write_bytes_atomic(dst, encode_image(v.load_image(), dst.suffix))
            mask = v.load_mask()
            if mask is not None:
                write_bytes_atomic(tmp / (scene.mask_dir or MASKS) / f"{v.stem}.png", encode_png(mask))
        colmap.write_model(
            tmp / "sparse" / "0",
            [v.name for v in scene.views],
            [v.camera for v in scene.views],
            [v.cam_from_world for v in scene.views],
            [(v.point_ids, v.uv) for v in scene.views],
            scene.points.xyz,
            scene.points.rgb,
            text=text,
        )
        meta = dict(scene.meta)
        meta["split"] = {"test": sorted(scene.test_names)}
        write_bytes_atomic(tmp / "scene.json", json.dumps(meta, indent=2, sort_keys=True).encode())
    return out


def linked_scene(source: Path | str, out: Path | str) -> Path:
    """A scene folder at ``out`` whose images, downsampled copies, COLMAP model and scene.json
    are symbolic links to those of ``source``: what is written into it (masks, caches) stays
    out of ``source``. Returns ``out``."""
    source, out = Path(source).resolve(), Path(out)
    if not (source / "sparse").is_dir():
        raise InputError(f"{source}: no sparse/ COLMAP model; make one with `python -m dataset_tools sfm`.")
    out.mkdir(parents=True, exist_ok=True)
    for entry in source.iterdir():
        if entry.name in ("sparse", "scene.json") or (entry.is_dir() and entry.name.split("_")[0] == IMAGES):
            link = out / entry.name
            if not link.exists():
                link.symlink_to(entry, target_is_directory=entry.is_dir())
    return out
