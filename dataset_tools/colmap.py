"""COLMAP models through pycolmap: reading, writing, and undistortion to pinhole cameras.

pycolmap is imported inside the functions (:func:`load_pycolmap`), never at module level:
importing it before the image libraries breaks every later PNG write (seen with pycolmap 4.2.1).
"""

from __future__ import annotations

import signal
import struct
import threading
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType

import cv2
import numpy as np

from dataset_tools.cameras import PINHOLE_MODELS, PinholeCamera, SourceCamera
from dataset_tools.infra.errors import InputError


def load_pycolmap() -> ModuleType:
    """pycolmap, with Python's SIGINT and SIGTERM handlers kept: on its first import its logging
    library installs its own, which print a native stack trace and kill the process where a
    command would stop cleanly with one line."""
    import pycolmap

    if threading.current_thread() is threading.main_thread():
        for number in (signal.SIGINT, signal.SIGTERM):
            handler = signal.getsignal(number)
            if handler is not None:
                signal.signal(number, handler)  # re-installs Python's own handler at the OS level
    return pycolmap


@dataclass
class ColmapImage:
    """One registered image of a COLMAP model, in the model's own (full-size) frame."""

    name: str
    camera: SourceCamera
    cam_from_world: np.ndarray  # (3, 4) float64
    point_ids: np.ndarray  # (M,) int64, rows of ColmapModel.xyz
    uv: np.ndarray  # (M, 2) float64, distorted pixel coordinates


@dataclass
class ColmapModel:
    images: list[ColmapImage]  # sorted by name
    xyz: np.ndarray  # (P, 3) float64
    rgb: np.ndarray  # (P, 3) uint8


def _check_cameras_bin(path: Path) -> None:
    """Refuse a binary camera file whose length is not the one its records declare (pycolmap
    reads a truncated one, filling the missing parameters with the last value read)."""
    pycolmap = load_pycolmap()

    if not path.is_file():
        return
    data = path.read_bytes()
    offset, expected = 8, None
    try:
        (count,) = struct.unpack_from("<Q", data, 0)
        for _ in range(count):
            _, model_id, _, _ = struct.unpack_from("<iiQQ", data, offset)
            n_params = len(pycolmap.Camera.create_from_model_id(0, pycolmap.CameraModelId(model_id), 1.0, 1, 1).params)
            offset += 24 + 8 * n_params
        expected = offset
    except (struct.error, ValueError, TypeError):
        pass
    if expected != len(data):
        raise InputError(
            f"{path}: {len(data)} bytes, not the length its camera records declare; the model is "
            "damaged, export it from COLMAP again."
        )


# The smallest record of each binary file: an image (id, rotation, translation, camera, an empty
# name, a point count), a 3D point (id, position, colour, error, an empty track).
SMALLEST_RECORD = {"images.bin": 4 + 32 + 24 + 4 + 1 + 8, "points3D.bin": 8 + 24 + 3 + 8 + 8}


def _check_record_counts(sparse_dir: Path) -> None:
    """Refuse a binary images or points file too short for the records its header counts (an
    empty or garbage file, which pycolmap would try to allocate for: minutes at full CPU, then
    std::bad_alloc)."""
    for name, smallest in SMALLEST_RECORD.items():
        path = sparse_dir / name
        if not path.is_file():
            continue
        size = path.stat().st_size
        with open(path, "rb") as f:
            header = f.read(8)
        count = struct.unpack("<Q", header)[0] if len(header) == 8 else None
        if count is None or 8 + count * smallest > size:
            raise InputError(
                f"{path}: {size} bytes, too short for the records its header counts; the model is damaged, "
                "export it from COLMAP again."
            )


def read_model(sparse_dir: Path) -> ColmapModel:
    """Read a binary or text COLMAP model (cameras, images, points3D) from ``sparse_dir``."""
    pycolmap = load_pycolmap()

    sparse_dir = Path(sparse_dir)
    if not sparse_dir.is_dir():
        raise InputError(
            f"{sparse_dir}: COLMAP model folder not found; run COLMAP (or `python -m dataset_tools "
            "synth`) so that the scene has sparse/0 with cameras, images and points3D."
        )
    _check_record_counts(sparse_dir)
    try:
        rec = pycolmap.Reconstruction(str(sparse_dir))
    except Exception as e:  # pycolmap raises plain RuntimeError/ValueError for broken files
        raise InputError(
            f"{sparse_dir}: not a readable COLMAP model ({str(e).strip().splitlines()[0]}); it needs "
            "cameras, images and points3D as .bin or .txt files."
        ) from None
    _check_cameras_bin(sparse_dir / "cameras.bin")
    for camera_id, cam in rec.cameras.items():
        params = np.asarray(cam.params, float)
        focal = params[cam.focal_length_idxs()] if len(params) else params
        cx, cy = params[cam.principal_point_idxs()] if len(params) else (-1.0, -1.0)
        if (
            cam.width <= 0
            or cam.height <= 0
            or not np.isfinite(params).all()
            or (focal <= 0).any()
            or not (0 <= cx <= cam.width and 0 <= cy <= cam.height)
        ):
            raise InputError(
                f"{sparse_dir}: camera {camera_id} is {cam.width}x{cam.height} with parameters "
                f"{params.round(3).tolist()}; the model is damaged, export it from COLMAP again."
            )
    point_ids = sorted(rec.points3D.keys())
    row_of = {pid: row for row, pid in enumerate(point_ids)}
    xyz = np.array([rec.points3D[p].xyz for p in point_ids], dtype=np.float64).reshape(-1, 3)
    rgb = np.array([rec.points3D[p].color for p in point_ids], dtype=np.uint8).reshape(-1, 3)
    images = []
    for image in rec.images.values():
        if not image.has_pose:
            continue
        cam = rec.cameras[image.camera_id]
        obs = [(row_of[p.point3D_id], p.xy) for p in image.points2D if p.has_point3D()]
        images.append(
            ColmapImage(
                name=image.name,
                camera=SourceCamera(cam.model.name, cam.width, cam.height, tuple(float(x) for x in cam.params)),
                cam_from_world=np.asarray(image.cam_from_world().matrix(), dtype=np.float64),
                point_ids=np.array([o[0] for o in obs], dtype=np.int64),
                uv=np.array([o[1] for o in obs], dtype=np.float64).reshape(-1, 2),
            )
        )
    if not images:
        raise InputError(f"{sparse_dir}: the COLMAP model has no registered images; re-run the reconstruction.")
    images.sort(key=lambda im: im.name)
    return ColmapModel(images=images, xyz=xyz, rgb=rgb)


def write_model(
    sparse_dir: Path,
    names: list[str],
    cameras: list[PinholeCamera],
    cam_from_world: list[np.ndarray],
    observations: list[tuple[np.ndarray, np.ndarray]],
    xyz: np.ndarray,
    rgb: np.ndarray,
    *,
    text: bool = False,
) -> None:
    """Write a COLMAP model of pinhole cameras.

    Args:
        names: image file names, one per view.
        cameras: one pinhole camera per view; identical cameras are shared.
        cam_from_world: (3, 4) world-to-camera transforms.
        observations: per view, (point_ids (M,) rows of ``xyz``, uv (M, 2) pixel coordinates).
        xyz: (P, 3) point positions. rgb: (P, 3) uint8 point colours.
    """
    pycolmap = load_pycolmap()

    rec = pycolmap.Reconstruction()
    camera_ids: dict[PinholeCamera, int] = {}
    for cam in cameras:
        if cam not in camera_ids:
            camera_ids[cam] = len(camera_ids) + 1
            rec.add_camera_with_trivial_rig(
                pycolmap.Camera(
                    model="PINHOLE",
                    width=cam.width,
                    height=cam.height,
                    params=[cam.fx, cam.fy, cam.cx, cam.cy],
                    camera_id=camera_ids[cam],
                )
            )
    tracks = [pycolmap.Track() for _ in range(len(xyz))]
    for image_id, (name, cam, T, (pids, uv)) in enumerate(
        zip(names, cameras, cam_from_world, observations, strict=True), start=1
    ):
        image = pycolmap.Image(
            name=name,
            keypoints=np.asarray(uv, dtype=np.float64).reshape(-1, 2),
            camera_id=camera_ids[cam],
            image_id=image_id,
        )
        T = np.asarray(T, dtype=np.float64)
        pose = pycolmap.Rigid3d(pycolmap.Rotation3d(T[:, :3]), T[:, 3])
        rec.add_image_with_trivial_frame(image, pose)
        for k, pid in enumerate(np.asarray(pids)):
            tracks[int(pid)].add_element(image_id, k)
    for p in range(len(xyz)):
        point_id = rec.add_point3D(np.asarray(xyz[p], dtype=np.float64), tracks[p], np.asarray(rgb[p], np.uint8))
        for el in tracks[p].elements:
            rec.image(el.image_id).set_point3D_for_point2D(el.point2D_idx, point_id)
    sparse_dir = Path(sparse_dir)
    sparse_dir.mkdir(parents=True, exist_ok=True)
    if text:
        rec.write_text(str(sparse_dir))
    else:
        rec.write_binary(str(sparse_dir))


def _pycolmap_camera(cam: SourceCamera):
    pycolmap = load_pycolmap()

    return pycolmap.Camera(model=cam.model, width=cam.width, height=cam.height, params=list(cam.params))


def resize_source_camera(cam: SourceCamera, width: int, height: int) -> SourceCamera:
    """The same lens for an image file resampled to ``width`` x ``height``."""
    if (width, height) == (cam.width, cam.height):
        return cam
    pc = _pycolmap_camera(cam)
    pc.rescale(width, height)
    return SourceCamera(cam.model, width, height, tuple(float(x) for x in pc.params))


def pinhole_camera(cam: SourceCamera) -> PinholeCamera:
    """The pinhole camera of an image: itself for pinhole models, else COLMAP's undistorted camera."""
    pycolmap = load_pycolmap()

    if cam.model in PINHOLE_MODELS:
        p = cam.params
        fx, fy, cx, cy = (p[0], p[0], p[1], p[2]) if cam.model == "SIMPLE_PINHOLE" else p
        return PinholeCamera(cam.width, cam.height, fx, fy, cx, cy)
    try:
        und = pycolmap.undistort_camera(pycolmap.UndistortCameraOptions(), _pycolmap_camera(cam))
    except Exception as e:
        raise InputError(
            f"camera model {cam.model} cannot be undistorted here ({e}); undistort the scene with "
            "`colmap image_undistorter` and load its output instead."
        ) from None
    fx, fy, cx, cy = und.params
    return PinholeCamera(und.width, und.height, float(fx), float(fy), float(cx), float(cy))


def undistort_points(uv: np.ndarray, source: SourceCamera, target: PinholeCamera) -> np.ndarray:
    """Move pixel coordinates from a distorted image to its pinhole image. (M, 2) -> (M, 2)."""
    if len(uv) == 0:
        return np.zeros((0, 2))
    normalized = _pycolmap_camera(source).cam_from_img(np.asarray(uv, dtype=np.float64))
    return normalized * [target.fx, target.fy] + [target.cx, target.cy]


def undistortion_maps(source: SourceCamera, target: PinholeCamera) -> tuple[np.ndarray, np.ndarray]:
    """cv2.remap maps that resample a distorted image into its pinhole image.

    Returns (map_x, map_y), each (target.height, target.width) float32, in OpenCV's
    integer-centred pixel coordinates of the source image.
    """
    u, v = np.meshgrid(np.arange(target.width) + 0.5, np.arange(target.height) + 0.5)
    rays = np.stack([(u - target.cx) / target.fx, (v - target.cy) / target.fy, np.ones_like(u)], -1)
    src = _pycolmap_camera(source).img_from_cam(rays.reshape(-1, 3), check_cheirality=False) - 0.5
    src = src.reshape(target.height, target.width, 2).astype(np.float32)
    return src[..., 0], src[..., 1]


def distortion_maps(source: SourceCamera, target: PinholeCamera) -> tuple[np.ndarray, np.ndarray]:
    """cv2.remap maps that resample a pinhole image back into the distorted image's frame
    (the inverse of :func:`undistortion_maps`).

    Returns (map_x, map_y), each (source.height, source.width) float32, in OpenCV's
    integer-centred pixel coordinates of the pinhole image.
    """
    u, v = np.meshgrid(np.arange(source.width) + 0.5, np.arange(source.height) + 0.5)
    dst = undistort_points(np.stack([u.ravel(), v.ravel()], 1), source, target) - 0.5
    dst = dst.reshape(source.height, source.width, 2).astype(np.float32)
    return dst[..., 0], dst[..., 1]


def remap(image: np.ndarray, maps: tuple[np.ndarray, np.ndarray], *, nearest: bool) -> np.ndarray:
    """Resample an image (bilinear) or an ID map (nearest) through undistortion maps."""
    interp = cv2.INTER_NEAREST if nearest else cv2.INTER_LINEAR
    return cv2.remap(image, maps[0], maps[1], interp, borderMode=cv2.BORDER_REPLICATE)
