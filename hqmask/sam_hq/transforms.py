"""SAM's input geometry: resize the longest side to the model size, normalise, pad.

The image is resized so that its longest side is ``image_size`` (1024), rounding each side
to the nearest pixel, with PIL's antialiased bilinear filter as SAM's ``ResizeLongestSide``
does; it is normalised by the pixel mean/std and zero-padded at the bottom and right to a
square. Prompt coordinates (x, y in the original image's pixels) scale by the same per-axis
factors.
"""

from __future__ import annotations

import numpy as np
from PIL import Image


def resized_shape(height: int, width: int, image_size: int) -> tuple[int, int]:
    """(h, w) of an image of ``height`` x ``width`` once its longest side is ``image_size``."""
    scale = image_size / max(height, width)
    return int(height * scale + 0.5), int(width * scale + 0.5)


def preprocess(image: np.ndarray, image_size: int, pixel_mean: np.ndarray, pixel_std: np.ndarray) -> np.ndarray:
    """The encoder input of ``image`` (H, W, 3) uint8 RGB: (1, 3, S, S) float32, S = ``image_size``.

    ``pixel_mean`` and ``pixel_std`` (3,) are in 0..255 units.
    """
    h, w = resized_shape(*image.shape[:2], image_size)
    resized = np.asarray(Image.fromarray(image).resize((w, h), Image.BILINEAR), np.float32)
    out = np.zeros((1, 3, image_size, image_size), np.float32)
    out[0, :, :h, :w] = ((resized - pixel_mean) / pixel_std).transpose(2, 0, 1)
    return out


def transform_coords(coords: np.ndarray, original_hw: tuple[int, int], image_size: int) -> np.ndarray:
    """Pixel coordinates (..., 2) as (x, y) in the original image -> the model's input frame."""
    h, w = original_hw
    new_h, new_w = resized_shape(h, w, image_size)
    return np.asarray(coords, np.float32) * np.array([new_w / w, new_h / h], np.float32)
