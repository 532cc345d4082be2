"""Camera paths: a 360-degree ``orbit`` and an LLFF-like ``forward``-facing set."""

from __future__ import annotations

import numpy as np

UP = np.array([0.0, 0.0, 1.0])


def look_at(eye: np.ndarray, target: np.ndarray) -> np.ndarray:
    """World-to-camera (3, 4) transform of a camera at ``eye`` looking at ``target``,
    with COLMAP axes (x right, y down, z forward) and world +z up."""
    f = target - eye
    f = f / np.linalg.norm(f)
    r = np.cross(f, UP)
    r = r / np.linalg.norm(r)
    d = np.cross(f, r)
    R = np.stack([r, d, f])
    return np.concatenate([R, (-R @ eye)[:, None]], axis=1)


def orbit(n: int, radius: float, target: np.ndarray) -> list[np.ndarray]:
    """``n`` cameras evenly around a full circle, elevation gently varying in 18..34 degrees."""
    poses = []
    for k in range(n):
        az = 2 * np.pi * k / n
        el = np.deg2rad(26 + 8 * np.sin(4 * np.pi * k / n))
        eye = target + radius * np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
        poses.append(look_at(eye, target))
    return poses


def forward(n: int, distance: float, target: np.ndarray, spread: float = 0.18) -> list[np.ndarray]:
    """``n`` cameras on a spiral in a plane facing the scene from -y (LLFF-like capture).

    The spiral spans ``spread * distance`` sideways; all cameras look at ``target``.
    """
    base = target + np.array([0.0, -distance * np.cos(np.deg2rad(20)), distance * np.sin(np.deg2rad(20))])
    poses = []
    for k in range(n):
        s = (k + 0.5) / n
        ang = 2 * np.pi * 2.5 * s
        offset = spread * distance * np.sqrt(s) * np.array([np.cos(ang), 0.0, 0.6 * np.sin(ang)])
        poses.append(look_at(base + offset, target))
    return poses
