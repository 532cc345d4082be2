"""What makes a scene the scene: each view's image size, pinhole camera, pose and image
content. A run records its scene's fingerprint when it trains; a command that is handed a
scene compares the two, so that another scene whose views merely share the names is refused
(a scene that moved, or was copied, is the same scene)."""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

from dataset_tools.scene import Scene, View

# Cameras and poses are compared to this relative tolerance (they pass through JSON and float32).
TOLERANCE = 1e-5


def file_digest(path: Path) -> str:
    """blake2b of a file's bytes, 32 hex digits (about 1 s a GB)."""
    h = hashlib.blake2b(digest_size=16)
    with open(path, "rb") as f:
        while chunk := f.read(1 << 20):
            h.update(chunk)
    return h.hexdigest()


def view_fingerprint(view: View) -> dict:
    """``size`` [W, H], ``camera`` [fx, fy, cx, cy], ``pose`` (12 floats of cam_from_world) and
    ``image`` (the file's digest) of one view."""
    c = view.camera
    return {
        "size": [c.width, c.height],
        "camera": [c.fx, c.fy, c.cx, c.cy],
        "pose": np.asarray(view.cam_from_world, float).ravel().tolist(),
        "image": file_digest(view.image_path),
    }


def scene_fingerprint(scene: Scene) -> dict:
    """The fingerprint of a loaded scene: its image folder and every view's
    :func:`view_fingerprint`, by view name."""
    return {"images": scene.image_dir, "views": {v.name: view_fingerprint(v) for v in scene.views}}


def _close(a: list[float], b: list[float]) -> bool:
    return len(a) == len(b) and np.allclose(a, b, rtol=TOLERANCE, atol=TOLERANCE)


def _view_difference(name: str, recorded: dict, now: dict) -> str | None:
    if recorded["size"] != now["size"]:
        return f"view {name} is {now['size'][0]}x{now['size'][1]}, not {recorded['size'][0]}x{recorded['size'][1]}"
    if not _close(recorded["camera"], now["camera"]):
        return (
            f"the camera of view {name} differs (fx, fy, cx, cy {np.round(now['camera'], 2).tolist()} against "
            f"{np.round(recorded['camera'], 2).tolist()})"
        )
    if not _close(recorded["pose"], now["pose"]):
        return f"the pose of view {name} differs"
    if recorded["image"] != now["image"]:
        return f"the image of view {name} differs"
    return None


def fingerprint_difference(recorded: dict, scene: Scene) -> str | None:
    """What differs between a recorded fingerprint and ``scene``, in words, or None when the
    scene is the recorded one. Views of another image folder are compared by name alone."""
    names = set(recorded["views"])
    present = {v.name for v in scene.views}
    if names - present:
        missing = sorted(names - present)
        return f"{len(missing)} of its views are missing, e.g. {missing[0]}"
    if present - names:
        extra = sorted(present - names)
        return f"it has {len(extra)} views the recorded scene did not, e.g. {extra[0]}"
    if scene.image_dir != recorded["images"]:
        return None
    for view in scene.views:
        difference = _view_difference(view.name, recorded["views"][view.name], view_fingerprint(view))
        if difference is not None:
            return difference
    return None
