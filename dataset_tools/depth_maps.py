"""Depth maps of a scene's views, where a trained model meets the mask stage.

``gsseg render --what depth`` writes one ``<stem>.npy`` per view: an (H, W) float32 array
of camera depth (the distance along the view's axis, in the scene's units) at the view's
image size, 0 where nothing opaque lies (sky, or past the model). ``hqmask build --depth
DIR`` reads them back.
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from dataset_tools.infra.atomic import write_bytes_atomic
from dataset_tools.infra.errors import InputError


def write_depth(path: Path, depth: np.ndarray) -> None:
    """Atomically write an (H, W) depth map as float32 ``.npy``."""
    if depth.ndim != 2:
        raise ValueError(f"depth: expected an (H, W) array, got shape {depth.shape}")
    buf = io.BytesIO()
    np.save(buf, np.ascontiguousarray(depth, dtype=np.float32), allow_pickle=False)
    write_bytes_atomic(Path(path), buf.getvalue())


def read_depth(path: Path, size: tuple[int, int]) -> np.ndarray:
    """The depth map at ``path``, checked against the view's ``size`` (width, height).
    Returns (H, W) float32, 0 where nothing is opaque."""
    fix = "render it again with `gsseg render RUN --what depth --split all --images IMAGES`"
    try:
        depth = np.load(path, allow_pickle=False)
    except FileNotFoundError:
        raise InputError(f"{path}: depth map not found; {fix}.") from None
    except (OSError, ValueError) as e:
        raise InputError(f"{path}: not a depth map ({e}); {fix}.") from None
    if not np.issubdtype(depth.dtype, np.floating):
        raise InputError(f"{path}: a map of {depth.dtype}, not of floating-point depths; {fix}.")
    if depth.shape != (size[1], size[0]):
        raise InputError(
            f"{path}: a map of shape {depth.shape}, but the view is {size[0]}x{size[1]}; {fix} (the image folder "
            "the masks are built on)."
        )
    depth = depth.astype(np.float32)
    if not np.isfinite(depth).all() or (depth < 0).any():
        raise InputError(f"{path}: holds negative or non-finite depths; {fix}.")
    return depth
