"""Reading and writing RGB images and 8-bit object-ID maps."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
from PIL import Image

from dataset_tools.infra.atomic import atomic_directory, write_bytes_atomic
from dataset_tools.infra.errors import InputError

IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png", ".JPG", ".JPEG", ".PNG")


def image_size(path: Path) -> tuple[int, int]:
    """(width, height) of an image file, read from its header only."""
    try:
        with Image.open(path) as im:
            return im.size
    except FileNotFoundError:
        raise InputError(
            f"{path}: image file not found; restore it or remove the view from the COLMAP model."
        ) from None
    except OSError as e:
        raise InputError(f"{path}: not a readable image ({e}); replace it with a JPEG or PNG.") from None


def read_image(path: Path) -> np.ndarray:
    """Read an RGB image as its pixels are stored (no EXIF rotation: COLMAP's cameras describe
    the stored pixels). Returns (H, W, 3) uint8. A truncated or damaged file is an error, not
    an image with grey rows."""
    try:
        with Image.open(path) as im:
            im.load()
            return np.array(im.convert("RGB"))
    except FileNotFoundError:
        raise InputError(
            f"{path}: image file not found; restore it or remove the view from the COLMAP model."
        ) from None
    except (OSError, SyntaxError, ValueError) as e:
        raise InputError(f"{path}: cannot read this image ({e}); replace it with a whole JPEG or PNG.") from None


def encode_image(rgb: np.ndarray, suffix: str) -> bytes:
    """The bytes of an (H, W, 3) uint8 RGB image as a ``.jpg``/``.jpeg`` (quality 95) or ``.png`` file."""
    jpeg = suffix.lower() in (".jpg", ".jpeg")
    ok, data = cv2.imencode(
        suffix.lower(), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, 95] if jpeg else []
    )
    if not ok:
        raise InputError(f"OpenCV cannot encode {suffix} images; use JPEG or PNG.")
    return data.tobytes()


def read_mask(path: Path) -> np.ndarray:
    """Read an object-ID map: an 8-bit single-channel PNG, or a palette PNG whose indices are
    the IDs. Returns (H, W) uint8, 0 = background, 1..255 = object IDs."""
    try:
        with Image.open(path) as im:
            im.load()
            mode, ids = im.mode, np.array(im)
    except FileNotFoundError:
        raise InputError(f"{path}: mask file not found; rebuild the masks with `hqmask build`.") from None
    except (OSError, SyntaxError, ValueError) as e:
        raise InputError(
            f"{path}: cannot read this mask ({e}); object masks must be 8-bit single-channel PNGs."
        ) from None
    if mode in ("L", "P"):
        return np.ascontiguousarray(ids, dtype=np.uint8)
    if mode == "1":
        return ids.astype(np.uint8)
    if ids.ndim == 3:
        raise InputError(
            f"{path}: mask has {ids.shape[2]} channels; object masks must be 8-bit single-channel "
            "PNGs of object IDs (convert colour masks to one ID per colour)."
        )
    if np.issubdtype(ids.dtype, np.integer) and ids.max(initial=0) > 255:
        raise InputError(
            f"{path}: mask holds IDs up to {int(ids.max())}, more than the 255 an 8-bit map can "
            "hold; merge or drop objects so that at most 255 IDs remain."
        )
    if np.issubdtype(ids.dtype, np.integer) and ids.min(initial=0) >= 0:
        return ids.astype(np.uint8)
    raise InputError(f"{path}: mask is {ids.dtype}; save it as an 8-bit single-channel PNG.")


def as_label_map(ids: np.ndarray, what: str) -> np.ndarray:
    """Check that an integer array fits an 8-bit ID map and return it as (H, W) uint8."""
    ids = np.asarray(ids)
    if ids.ndim != 2 or not np.issubdtype(ids.dtype, np.integer):
        raise InputError(f"{what}: an ID map must be a 2-D integer array, got {ids.dtype} {ids.shape}.")
    if ids.size and (ids.min() < 0 or ids.max() > 255):
        raise InputError(
            f"{what}: IDs range over [{int(ids.min())}, {int(ids.max())}] but must lie in 0..255; "
            "merge or drop objects so that at most 255 IDs remain."
        )
    return ids.astype(np.uint8, copy=False)


def encode_png(array: np.ndarray) -> bytes:
    """PNG bytes of an (H, W) uint8 map or an (H, W, 3) uint8 RGB image."""
    if array.ndim == 3:
        array = cv2.cvtColor(array, cv2.COLOR_RGB2BGR)
    ok, buf = cv2.imencode(".png", array)
    if not ok:
        raise RuntimeError("PNG encoding failed")
    return buf.tobytes()


def write_png(path: Path, array: np.ndarray) -> None:
    """Atomically write an (H, W) uint8 ID map or (H, W, 3) uint8 RGB image as PNG."""
    write_bytes_atomic(Path(path), encode_png(np.ascontiguousarray(array)))


def label_palette() -> np.ndarray:
    """A fixed colour for every ID: (256, 3) uint8, ID 0 black, neighbours well apart."""
    ids = np.arange(256)
    hue = (ids * 0.618033988749895) % 1.0
    sat = 0.55 + 0.45 * ((ids * 7) % 3) / 2
    val = 0.75 + 0.25 * ((ids * 5) % 2)
    hsv = np.stack([hue * 180, sat * 255, val * 255], axis=-1).astype(np.uint8)[None]
    rgb = cv2.cvtColor(hsv, cv2.COLOR_HSV2RGB)[0]
    rgb[0] = 0
    return rgb


def colorize_labels(ids: np.ndarray) -> np.ndarray:
    """Colour an ID map for viewing. (H, W) integer -> (H, W, 3) uint8."""
    return label_palette()[np.asarray(ids, dtype=np.uint8)]


def write_downsampled(src: Path, dst: Path, factor: int) -> None:
    """Write every image of ``src`` (JPEG or PNG, sub-folders too) to ``dst`` at 1/``factor``
    size (area filter), with the same names and formats: the ``images_N`` copies a scene folder
    may hold. ``dst`` appears whole or not at all."""
    files = sorted(p for p in Path(src).rglob("*") if p.suffix in IMAGE_SUFFIXES)
    if not files:
        raise InputError(f"{src}: no JPEG or PNG images to downsample.")
    with atomic_directory(Path(dst)) as tmp:
        for f in files:
            image = read_image(f)
            size = (max(1, image.shape[1] // factor), max(1, image.shape[0] // factor))
            small = cv2.resize(image, size, interpolation=cv2.INTER_AREA)
            write_bytes_atomic(tmp / f.relative_to(src), encode_image(small, f.suffix))
