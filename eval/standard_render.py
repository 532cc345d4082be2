"""A reference renderer of 3D-GS PLY files, independent of the project's rasterizer, to check
that an export looks in other viewers as it looks here: the conventions of the original 3D-GS
rasterizer (EWA splatting with its 0.3 px low-pass, 3-sigma extents, opacity
capped at 0.99, alphas under 1/255 skipped, front-to-back compositing by view depth that
stops below a transmittance of 1e-4, SH evaluated at the direction from the camera centre
plus 0.5, clamped at 0) written from the paper in NumPy, composited one Gaussian at a time
(compiled by numba). It reads the file with plyfile alone and shares no code with the
project's renderer or PLY reader."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numba import njit
from plyfile import PlyData

SH_C0 = 0.28209479177387814
SH_C1 = 0.4886025119029199
SH_C2 = (1.0925484305920792, -1.0925484305920792, 0.31539156525252005, -1.0925484305920792, 0.5462742152960396)
SH_C3 = (
    -0.5900435899266435,
    2.890611442640554,
    -0.4570457994644658,
    0.3731763325901154,
    -0.4570457994644658,
    1.445305721320277,
    -0.5900435899266435,
)
NEAR = 0.2


def read_splats(path: Path) -> dict[str, np.ndarray]:
    """means (N, 3), scales (N, 3), rotations (N, 3, 3), opacities (N,), sh (N, K, 3)."""
    v = PlyData.read(str(path))["vertex"].data
    means = np.stack([v["x"], v["y"], v["z"]], 1).astype(np.float64)
    scales = np.exp(np.stack([v[f"scale_{i}"] for i in range(3)], 1).astype(np.float64))
    q = np.stack([v[f"rot_{i}"] for i in range(4)], 1).astype(np.float64)
    w, x, y, z = (q / np.linalg.norm(q, axis=1, keepdims=True)).T
    rotations = np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], 1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], 1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], 1),
        ],
        1,
    )
    rest = sorted((n for n in v.dtype.names if n.startswith("f_rest_")), key=lambda n: int(n.split("_")[-1]))
    dc = np.stack([v[f"f_dc_{i}"] for i in range(3)], 1)[:, None]
    sh = (
        dc
        if not rest
        else np.concatenate([dc, np.stack([v[n] for n in rest], 1).reshape(len(v), 3, -1).transpose(0, 2, 1)], 1)
    )
    return {
        "means": means,
        "scales": scales,
        "rotations": rotations,
        "opacities": 1 / (1 + np.exp(-v["opacity"].astype(np.float64))),
        "sh": sh.astype(np.float64),
    }


def _sh_colour(sh: np.ndarray, d: np.ndarray) -> np.ndarray:
    x, y, z = d.T
    basis = [np.full_like(x, SH_C0)]
    k = sh.shape[1]
    if k > 1:
        basis += [-SH_C1 * y, SH_C1 * z, -SH_C1 * x]
    if k > 4:
        basis += [
            SH_C2[0] * x * y,
            SH_C2[1] * y * z,
            SH_C2[2] * (2 * z * z - x * x - y * y),
            SH_C2[3] * x * z,
            SH_C2[4] * (x * x - y * y),
        ]
    if k > 9:
        basis += [
            SH_C3[0] * y * (3 * x * x - y * y),
            SH_C3[1] * x * y * z,
            SH_C3[2] * y * (4 * z * z - x * x - y * y),
            SH_C3[3] * z * (2 * z * z - 3 * x * x - 3 * y * y),
            SH_C3[4] * x * (4 * z * z - x * x - y * y),
            SH_C3[5] * z * (x * x - y * y),
            SH_C3[6] * x * (x * x - 3 * y * y),
        ]
    return np.maximum(np.einsum("nk,nkc->nc", np.stack(basis, 1), sh) + 0.5, 0.0)


def render_reference(
    splats: dict[str, np.ndarray],
    fx: float,
    fy: float,
    cx: float,
    cy: float,
    width: int,
    height: int,
    cam_from_world: np.ndarray,
) -> np.ndarray:
    """(H, W, 3) float image of ``splats`` on black, pixel (i, j) sampled at (i + 0.5, j + 0.5)."""
    Rw, t = cam_from_world[:, :3], cam_from_world[:, 3]
    p = splats["means"] @ Rw.T + t
    keep = p[:, 2] > NEAR
    p, idx = p[keep], np.nonzero(keep)[0]
    lim_x, lim_y = 1.3 * 0.5 * width / fx, 1.3 * 0.5 * height / fy
    tx = np.clip(p[:, 0] / p[:, 2], -lim_x, lim_x) * p[:, 2]
    ty = np.clip(p[:, 1] / p[:, 2], -lim_y, lim_y) * p[:, 2]
    z = p[:, 2]
    J = np.zeros((len(p), 2, 3))
    J[:, 0, 0], J[:, 0, 2] = fx / z, -fx * tx / z**2
    J[:, 1, 1], J[:, 1, 2] = fy / z, -fy * ty / z**2
    M = splats["rotations"][idx] * splats["scales"][idx][:, None, :]
    T = J @ Rw[None] @ M
    cov = T @ T.transpose(0, 2, 1) + 0.3 * np.eye(2)
    det = cov[:, 0, 0] * cov[:, 1, 1] - cov[:, 0, 1] ** 2
    u, v = fx * p[:, 0] / z + cx, fy * p[:, 1] / z + cy
    mid = 0.5 * (cov[:, 0, 0] + cov[:, 1, 1])
    radius = np.ceil(3 * np.sqrt(mid + np.sqrt(np.maximum(0.1, mid * mid - det))))
    on = (det > 0) & (u + radius > 0) & (u - radius < width) & (v + radius > 0) & (v - radius < height)
    center = -Rw.T @ t
    dirs = splats["means"][idx] - center
    colour = _sh_colour(splats["sh"][idx], dirs / np.linalg.norm(dirs, axis=1, keepdims=True))
    order = np.nonzero(on)[0][np.argsort(z[on], kind="stable")]
    return _composite(order, u, v, radius, cov, det, splats["opacities"][idx], colour, width, height)


@njit(cache=True)
def _composite(
    order: np.ndarray,
    u: np.ndarray,
    v: np.ndarray,
    radius: np.ndarray,
    cov: np.ndarray,
    det: np.ndarray,
    opacities: np.ndarray,
    colour: np.ndarray,
    width: int,
    height: int,
) -> np.ndarray:
    """(H, W, 3): the Gaussians ``order`` (front to back) composited one at a time, each over
    its 3-sigma box, every pixel stopping before the Gaussian that takes its transmittance
    under 1e-4."""
    image = np.zeros((height, width, 3))
    trans = np.ones((height, width))
    done = np.zeros((height, width), np.bool_)
    for k in order:
        x0, x1 = int(max(0.0, u[k] - radius[k])), int(min(width, u[k] + radius[k] + 1))
        y0, y1 = int(max(0.0, v[k] - radius[k])), int(min(height, v[k] + radius[k] + 1))
        a, b, c = cov[k, 1, 1] / det[k], -cov[k, 0, 1] / det[k], cov[k, 0, 0] / det[k]
        for y in range(y0, y1):
            dy = y + 0.5 - v[k]
            for x in range(x0, x1):
                if done[y, x]:
                    continue
                dx = x + 0.5 - u[k]
                power = -0.5 * (a * dx * dx + c * dy * dy) - b * dx * dy
                if power > 0:
                    continue
                alpha = min(0.99, opacities[k] * np.exp(power))
                if alpha < 1 / 255:
                    continue
                t = trans[y, x]
                if t * (1 - alpha) < 1e-4:  # that pixel stops before this Gaussian
                    done[y, x] = True
                    continue
                for ch in range(3):
                    image[y, x, ch] += t * alpha * colour[k, ch]
                trans[y, x] = t * (1 - alpha)
    return image
