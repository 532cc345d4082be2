"""Procedural solid textures: albedo as a function of the 3D surface point."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numba
import numpy as np

Pattern = Literal["checker", "stripes", "waves", "plain", "speckle"]


def _smooth_square(x: np.ndarray, sharpness: float = 6.0) -> np.ndarray:
    """A square wave in [0, 1] with soft edges (limits aliasing at low resolution)."""
    return 0.5 + 0.5 * np.tanh(sharpness * np.sin(np.pi * x))


@numba.njit(cache=True, inline="always")
def _lattice(x: int, y: int, z: int) -> float:
    """A fixed pseudo-random value in [0, 1) at the integer lattice point (x, y, z) (an integer
    hash with xor-shift mixing, so that neighbouring points are unrelated)."""
    m = np.uint64(0xFFFFFFFF)
    h = ((np.uint64(x) & m) * np.uint64(0x9E3779B1)) ^ ((np.uint64(y) & m) * np.uint64(0x85EBCA77))
    h = (h ^ ((np.uint64(z) & m) * np.uint64(0xC2B2AE3D))) & m
    h = ((h ^ (h >> np.uint64(15))) * np.uint64(0x2C1B3C6D)) & m
    h = ((h ^ (h >> np.uint64(12))) * np.uint64(0x297A2D39)) & m
    h = (h ^ (h >> np.uint64(15))) & m
    return h / 2.0**32


@numba.njit(inline="always")
def _cell(p: float) -> tuple[int, float]:
    """The lattice cell below ``p`` and the smoothstep weight of ``p`` within it."""
    base = np.floor(p)
    f = p - base
    return np.int64(base), f * f * (3 - 2 * f)


@numba.njit(cache=True, parallel=True)
def value_noise(q: np.ndarray, octaves: int = 4) -> np.ndarray:
    """Multi-octave value noise in [0, 1] at points ``q`` (N, 3): trilinear interpolation
    (smoothstep weights) of lattice values, each octave twice as fine and half as strong.
    Irregular blobs at every scale: corners for feature matching, unlike periodic patterns.
    Each point on its own, so the values do not depend on the threads."""
    out = np.empty(q.shape[0])
    for i in numba.prange(q.shape[0]):
        total, norm = 0.0, 0.0
        for octave in range(octaves):
            scale = 2.0**octave
            bx, wx = _cell(q[i, 0] * scale)
            by, wy = _cell(q[i, 1] * scale)
            bz, wz = _cell(q[i, 2] * scale)
            value = 0.0
            for cx in range(2):
                for cy in range(2):
                    for cz in range(2):
                        weight = (wx if cx else 1 - wx) * (wy if cy else 1 - wy) * (wz if cz else 1 - wz)
                        value += weight * _lattice(bx + cx, by + cy, bz + cz)
            total += value * 0.5**octave
            norm += 0.5**octave
        out[i] = total / norm
    return out


def _soft_xor(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return a + b - 2 * a * b


@dataclass(frozen=True)
class Texture:
    """Mix of two colours by a pattern evaluated in the object's frame.

    ``origin`` and ``scale`` map world points into pattern coordinates; ``axis`` orients
    stripes; ``fade`` (world units, 0 = none) lowers the contrast far from ``origin``.
    """

    pattern: Pattern
    color_a: tuple[float, float, float]
    color_b: tuple[float, float, float]
    origin: tuple[float, float, float] = (0.0, 0.0, 0.0)
    scale: float = 1.0
    axis: tuple[float, float, float] = (0.0, 0.0, 1.0)
    fade: float = 0.0

    def albedo(self, points: np.ndarray) -> np.ndarray:
        """Albedo in [0, 1] of surface points. (N, 3) -> (N, 3)."""
        q = (points - np.asarray(self.origin)) / self.scale
        if self.pattern == "checker":
            sx, sy, sz = _smooth_square(q[:, 0]), _smooth_square(q[:, 1]), _smooth_square(q[:, 2] + 0.5)
            w = _soft_xor(_soft_xor(sx, sy), sz)
        elif self.pattern == "stripes":
            w = _smooth_square(q @ np.asarray(self.axis))
        elif self.pattern == "speckle":
            w = 0.5 + 1.6 * (value_noise(q) - 0.5)
        elif self.pattern == "waves":
            w = (
                0.5
                + 0.25 * np.sin(2.1 * q[:, 0] + 1.3 * np.sin(1.7 * q[:, 2]))
                + 0.25 * np.sin(1.9 * q[:, 1] - 0.7 * q[:, 2])
            )
        else:
            w = np.zeros(len(points))
        if self.fade > 0:
            r2 = np.sum((points - np.asarray(self.origin))[:, :2] ** 2, axis=1)
            w = 0.5 + (w - 0.5) * np.exp(-r2 / self.fade**2)
        a, b = np.asarray(self.color_a), np.asarray(self.color_b)
        return a + (b - a) * np.clip(w, 0.0, 1.0)[:, None]
