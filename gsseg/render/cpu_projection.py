"""The ``cpu`` backend's projection: :func:`gsseg.render.projection.project_gaussians` as
numba kernels, forward and backward, one Gaussian at a time.

The tensor version spends most of its time in the overhead of some thirty small operations
on (N, 3, 3) and (N, 2, 3) tensors and their autograd; here each Gaussian's projection and
its gradient are a few hundred scalar operations, in float64, over Gaussians split between
threads (each writes its own rows, so the results do not depend on the threads). The maths
is the tensor version's, line by line (the tests compare both); the backward pass is that
chain written out:

    conic = (c, -b, a) / det,  det = a c - b^2,  (a, b, c) = (|T0|^2 + eps, T0.T1, |T1|^2 + eps)
    T = J R M,  M = R_q diag(s),  J = the Jacobian of the pinhole at the camera-space centre p
    means2d = (fx px / pz + cx, fy py / pz + cy),  depth = pz,  p = R m + t
"""

from __future__ import annotations

import math

import numba
import numpy as np
import torch

from dataset_tools.cameras import PinholeCamera
from gsseg.render.blend_rules import ALPHA_MIN
from gsseg.render.projection import EPS_2D, Projection, project_gaussians


@numba.njit(inline="always")
def _rotmat(q, out):
    """Fill out (3, 3) with the rotation of quaternion q (w, x, y, z) of unit norm."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    out[0, 0], out[0, 1], out[0, 2] = 1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)
    out[1, 0], out[1, 1], out[1, 2] = 2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)
    out[2, 0], out[2, 1], out[2, 2] = 2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)


@numba.njit(inline="always")
def _camera_point(means, i, rotation, translation, near, p):
    """Fill p (3,) with Gaussian i's camera-space centre; returns whether it is in front of
    the near plane and the depth the Jacobian uses (1 behind it, as the tensor version)."""
    for r in range(3):
        p[r] = rotation[r, 0] * means[i, 0] + rotation[r, 1] * means[i, 1] + rotation[r, 2] * means[i, 2]
        p[r] += translation[r]
    in_front = p[2] > near
    return in_front, p[2] if in_front else 1.0


@numba.njit(inline="always")
def _factor(quats, scales, i, jw, rq, qn, m, t):
    """Fill qn (4,) the unit quaternion, rq (3, 3) its rotation, m = rq diag(scales[i]) and
    t (2, 3) = jw m for Gaussian i."""
    norm = math.sqrt(quats[i, 0] ** 2 + quats[i, 1] ** 2 + quats[i, 2] ** 2 + quats[i, 3] ** 2)
    norm = max(norm, 1e-12)  # torch.nn.functional.normalize's eps
    for k in range(4):
        qn[k] = quats[i, k] / norm
    _rotmat(qn, rq)
    for r in range(3):
        for k in range(3):
            m[r, k] = rq[r, k] * scales[i, k]
    for r in range(2):
        for k in range(3):
            t[r, k] = jw[r, 0] * m[0, k] + jw[r, 1] * m[1, k] + jw[r, 2] * m[2, k]
    return norm


@numba.njit(inline="always")
def _jacobian(p, z, rotation, intrinsics, limits, jw):
    """Fill jw (2, 3) = J R for the camera-space centre p at Jacobian depth z; returns the
    clamped tx, ty and whether each is inside its limit."""
    fx, fy = intrinsics[0], intrinsics[1]
    ux, uy = p[0] / z, p[1] / z
    in_x, in_y = -limits[0] <= ux <= limits[0], -limits[1] <= uy <= limits[1]
    tx = z * min(max(ux, -limits[0]), limits[0])
    ty = z * min(max(uy, -limits[1]), limits[1])
    j00, j02, j11, j12 = fx / z, -fx * tx / (z * z), fy / z, -fy * ty / (z * z)
    for k in range(3):
        jw[0, k] = j00 * rotation[0, k] + j02 * rotation[2, k]
        jw[1, k] = j11 * rotation[1, k] + j12 * rotation[2, k]
    return tx, ty, in_x, in_y


@numba.njit(parallel=True, cache=True)
def project_forward(means, quats, scales, opacities, rotation, translation, intrinsics, size, near):
    """Project N Gaussians as :func:`gsseg.render.projection.project_gaussians` does.

    Args:
        means (N, 3), quats (N, 4), scales (N, 3), opacities (N,); rotation (3, 3) and
        translation (3,) world to camera; intrinsics (fx, fy, cx, cy); size (width, height).

    Returns:
        means2d (N, 2), conics (N, 3), depths (N,) float32 and radii (N,) int32.
    """
    n = means.shape[0]
    fx, fy, cx, cy = intrinsics[0], intrinsics[1], intrinsics[2], intrinsics[3]
    width, height = size[0], size[1]
    limits = np.array([1.3 * 0.5 * width / fx, 1.3 * 0.5 * height / fy])
    means2d = np.empty((n, 2), np.float32)
    conics = np.empty((n, 3), np.float32)
    depths = np.empty(n, np.float32)
    radii = np.zeros(n, np.int32)
    for i in numba.prange(n):
        p, qn = np.empty(3), np.empty(4)
        jw, rq, m, t = np.empty((2, 3)), np.empty((3, 3)), np.empty((3, 3)), np.empty((2, 3))
        in_front, z = _camera_point(means, i, rotation, translation, near, p)
        _jacobian(p, z, rotation, intrinsics, limits, jw)
        _factor(quats, scales, i, jw, rq, qn, m, t)
        a = t[0, 0] ** 2 + t[0, 1] ** 2 + t[0, 2] ** 2 + EPS_2D
        b = t[0, 0] * t[1, 0] + t[0, 1] * t[1, 1] + t[0, 2] * t[1, 2]
        c = t[1, 0] ** 2 + t[1, 1] ** 2 + t[1, 2] ** 2 + EPS_2D
        det = a * c - b * b
        valid = in_front and det > 0
        if not valid:
            det = 1.0
        conics[i, 0], conics[i, 1], conics[i, 2] = c / det, -b / det, a / det
        mx, my = fx * p[0] / z + cx, fy * p[1] / z + cy
        means2d[i, 0], means2d[i, 1] = mx, my
        depths[i] = p[2]
        mid = 0.5 * (a + c)
        lambda_max = mid + math.sqrt(max(mid * mid - det, 0.1))
        extent = math.sqrt(min(max(2.0 * math.log(opacities[i] / ALPHA_MIN), 0.0), 9.0))
        r = math.ceil(extent * math.sqrt(lambda_max))
        on_screen = mx + r > 0 and mx - r < width and my + r > 0 and my - r < height
        if valid and on_screen and r > 0:
            radii[i] = r
    return means2d, conics, depths, radii


@numba.njit(parallel=True, cache=True)
def project_backward(
    means, quats, scales, rotation, translation, intrinsics, size, near, radii, d_means2d, d_conics, d_depths
):
    """The gradients (N, 3), (N, 4), (N, 3) float32 of a loss with respect to means, quats
    and scales, given its gradients with respect to :func:`project_forward`'s means2d (N, 2),
    conics (N, 3) and depths (N,). Gaussians of radius 0 get none (nothing drawn them)."""
    n = means.shape[0]
    fx, fy = intrinsics[0], intrinsics[1]
    width, height = size[0], size[1]
    limits = np.array([1.3 * 0.5 * width / fx, 1.3 * 0.5 * height / fy])
    g_means = np.zeros((n, 3), np.float32)
    g_quats = np.zeros((n, 4), np.float32)
    g_scales = np.zeros((n, 3), np.float32)
    for i in numba.prange(n):
        if radii[i] == 0:
            continue
        p, qn = np.empty(3), np.empty(4)
        jw, rq, m, t = np.empty((2, 3)), np.empty((3, 3)), np.empty((3, 3)), np.empty((2, 3))
        _, z = _camera_point(means, i, rotation, translation, near, p)
        tx, ty, in_x, in_y = _jacobian(p, z, rotation, intrinsics, limits, jw)
        norm = _factor(quats, scales, i, jw, rq, qn, m, t)
        a = t[0, 0] ** 2 + t[0, 1] ** 2 + t[0, 2] ** 2 + EPS_2D
        b = t[0, 0] * t[1, 0] + t[0, 1] * t[1, 1] + t[0, 2] * t[1, 2]
        c = t[1, 0] ** 2 + t[1, 1] ** 2 + t[1, 2] ** 2 + EPS_2D
        det = a * c - b * b
        # conic = (c, -b, a) / det
        g0, g1, g2 = d_conics[i, 0], d_conics[i, 1], d_conics[i, 2]
        d_det = -(g0 * c - g1 * b + g2 * a) / (det * det)
        da, db, dc = g2 / det + d_det * c, -g1 / det - 2.0 * d_det * b, g0 / det + d_det * a
        # (a, b, c) from the rows of t
        dt = np.empty((2, 3))
        for k in range(3):
            dt[0, k] = 2.0 * da * t[0, k] + db * t[1, k]
            dt[1, k] = db * t[0, k] + 2.0 * dc * t[1, k]
        # t = jw m: into m (then rq and the scales) and jw (then J's entries, jw = J R)
        drq, d_jw = np.empty((3, 3)), np.zeros((2, 3))
        for k in range(3):
            ds = 0.0
            for r in range(3):
                dm = jw[0, r] * dt[0, k] + jw[1, r] * dt[1, k]
                ds += dm * rq[r, k]
                drq[r, k] = dm * scales[i, k]
                d_jw[0, r] += dt[0, k] * m[r, k]
                d_jw[1, r] += dt[1, k] * m[r, k]
            g_scales[i, k] = ds
        d_j00 = d_jw[0, 0] * rotation[0, 0] + d_jw[0, 1] * rotation[0, 1] + d_jw[0, 2] * rotation[0, 2]
        d_j02 = d_jw[0, 0] * rotation[2, 0] + d_jw[0, 1] * rotation[2, 1] + d_jw[0, 2] * rotation[2, 2]
        d_j11 = d_jw[1, 0] * rotation[1, 0] + d_jw[1, 1] * rotation[1, 1] + d_jw[1, 2] * rotation[1, 2]
        d_j12 = d_jw[1, 0] * rotation[2, 0] + d_jw[1, 1] * rotation[2, 1] + d_jw[1, 2] * rotation[2, 2]
        # J = [[fx / z, 0, -fx tx / z^2], [0, fy / z, -fy ty / z^2]], tx = z clamp(px / z)
        z2, z3 = z * z, z * z * z
        d_tx, d_ty = -fx * d_j02 / z2, -fy * d_j12 / z2
        dpx = d_tx if in_x else 0.0
        dpy = d_ty if in_y else 0.0
        dz = -fx * d_j00 / z2 - fy * d_j11 / z2 + 2.0 * fx * tx * d_j02 / z3 + 2.0 * fy * ty * d_j12 / z3
        if not in_x:
            dz += d_tx * tx / z
        if not in_y:
            dz += d_ty * ty / z
        # means2d and depth
        gm0, gm1 = d_means2d[i, 0], d_means2d[i, 1]
        dpx += gm0 * fx / z
        dpy += gm1 * fy / z
        dz += -gm0 * fx * p[0] / z2 - gm1 * fy * p[1] / z2 + d_depths[i]
        for k in range(3):
            g_means[i, k] = rotation[0, k] * dpx + rotation[1, k] * dpy + rotation[2, k] * dz
        # rq from the unit quaternion, then its normalisation
        w, x, y, zq = qn[0], qn[1], qn[2], qn[3]
        d = drq
        dw = 2.0 * (zq * (d[1, 0] - d[0, 1]) + y * (d[0, 2] - d[2, 0]) + x * (d[2, 1] - d[1, 2]))
        dx = 2.0 * (
            y * (d[0, 1] + d[1, 0]) + zq * (d[0, 2] + d[2, 0]) + w * (d[2, 1] - d[1, 2]) - 2 * x * (d[1, 1] + d[2, 2])
        )
        dy = 2.0 * (
            x * (d[0, 1] + d[1, 0]) + w * (d[0, 2] - d[2, 0]) + zq * (d[1, 2] + d[2, 1]) - 2 * y * (d[0, 0] + d[2, 2])
        )
        dzq = 2.0 * (
            w * (d[1, 0] - d[0, 1]) + x * (d[0, 2] + d[2, 0]) + y * (d[1, 2] + d[2, 1]) - 2 * zq * (d[0, 0] + d[1, 1])
        )
        dot = w * dw + x * dx + y * dy + zq * dzq
        g_quats[i, 0] = (dw - w * dot) / norm
        g_quats[i, 1] = (dx - x * dot) / norm
        g_quats[i, 2] = (dy - y * dot) / norm
        g_quats[i, 3] = (dzq - zq * dot) / norm
    return g_means, g_quats, g_scales


PROJECTION_KERNELS = (project_forward, project_backward)


class _ProjectCPU(torch.autograd.Function):
    @staticmethod
    def forward(ctx, means, quats, scales, opacities, rotation, translation, intrinsics, size, near):
        arrays = [np.ascontiguousarray(x.detach().numpy(), np.float32) for x in (means, quats, scales)]
        camera = (rotation, translation, intrinsics, size, near)
        means2d, conics, depths, radii = project_forward(
            *arrays, np.ascontiguousarray(opacities.detach().numpy(), np.float32), *camera
        )
        ctx.args = (*arrays, *camera, radii)
        radii = torch.from_numpy(radii)
        ctx.mark_non_differentiable(radii)
        return torch.from_numpy(means2d), torch.from_numpy(conics), torch.from_numpy(depths), radii

    @staticmethod
    def backward(ctx, d_means2d, d_conics, d_depths, _):
        grads = project_backward(
            *ctx.args, *(np.ascontiguousarray(g.numpy(), np.float32) for g in (d_means2d, d_conics, d_depths))
        )
        return (*(torch.from_numpy(g) for g in grads), None, None, None, None, None, None)


def project_gaussians_cpu(
    means: torch.Tensor,
    quats: torch.Tensor,
    scales: torch.Tensor,
    cam_from_world: torch.Tensor,
    camera: PinholeCamera,
    opacities: torch.Tensor,
) -> Projection:
    """:func:`gsseg.render.projection.project_gaussians` by the numba kernels for float32 CPU
    tensors (means (N, 3), quats (N, 4), scales (N, 3), opacities (N,)), by it otherwise;
    differentiable in means, quats and scales."""
    if means.dtype != torch.float32 or means.device.type != "cpu":
        return project_gaussians(means, quats, scales, cam_from_world, camera, opacities)
    pose = torch.as_tensor(cam_from_world).detach().double().numpy()
    means2d, conics, depths, radii = _ProjectCPU.apply(
        means,
        quats,
        scales,
        opacities,
        np.ascontiguousarray(pose[:3, :3]),
        np.ascontiguousarray(pose[:3, 3]),
        np.array([camera.fx, camera.fy, camera.cx, camera.cy], np.float64),
        np.array([camera.width, camera.height], np.int64),
        float(camera.near),
    )
    return Projection(means2d=means2d, conics=conics, depths=depths, radii=radii)
