"""The environment's background image on the CPU: numba kernels for it and its gradient.

The same image as :meth:`gsseg.model.environment.Environment.image_torch`, the torch reference the
tests compare with, computed pixel by pixel without the (H W, 16) table of SH basis values
that the tensor version builds: each pixel's ray direction, its SH colour (offset by 0.5 and
clamped at 0, as 3D-GS's colours are) and its elevation profile colour. The backward pass
recomputes them and sums the gradients of the SH coefficients and of the profile bins over
blocks of ``ROW_BLOCK`` rows, in float64, then over the blocks in order: the same bits
however the threads are scheduled. Every pixel is computed in float64, the image is float32.
"""

from __future__ import annotations

import math

import numba
import numpy as np
import torch

from dataset_tools.cameras import PinholeCamera
from gsseg.model.sh_cpu import sh_basis_at, sh_channel

ROW_BLOCK = 8  # rows whose gradients one block sums before the blocks are summed in order


@numba.njit(inline="always")
def _ray(rotation, intrinsics, u, v):
    """The unit world direction of the ray through pixel centre (u, v): R^T K^-1 (u, v, 1)."""
    fx, fy, cx, cy = intrinsics[0], intrinsics[1], intrinsics[2], intrinsics[3]
    a, b = (u - cx) / fx, (v - cy) / fy
    x = a * rotation[0, 0] + b * rotation[1, 0] + rotation[2, 0]
    y = a * rotation[0, 1] + b * rotation[1, 1] + rotation[2, 1]
    z = a * rotation[0, 2] + b * rotation[1, 2] + rotation[2, 2]
    n = math.sqrt(x * x + y * y + z * z)
    return x / n, y / n, z / n


@numba.njit(inline="always")
def _profile_bin(x, y, z, up, bins):
    """The two profile bins a direction falls between and the weight of the upper one."""
    s = min(max(x * up[0] + y * up[1] + z * up[2], -1.0), 1.0)
    t = (math.asin(s) / math.pi + 0.5) * bins - 0.5  # bin k's centre at t = k
    lo = min(max(math.floor(t), 0.0), bins - 1.0)
    w = min(max(t - lo, 0.0), 1.0)
    return int(lo), min(int(lo) + 1, bins - 1), w


@numba.njit(parallel=True, cache=True)
def environment_forward(rotation, intrinsics, width, height, coeffs, up, profile):
    """The background image (H, W, 3) float32 of a camera (world-to-camera ``rotation`` (3, 3),
    ``intrinsics`` (fx, fy, cx, cy)): SH ``coeffs`` (K, 3), K <= 16, plus the elevation
    ``profile`` (B, 3) about ``up`` (3,) (B = 0: none)."""
    n_k, bins = coeffs.shape[0], profile.shape[0]
    image = np.empty((height, width, 3), np.float32)
    for i in numba.prange(height):
        basis = np.empty(16)
        for j in range(width):
            x, y, z = _ray(rotation, intrinsics, j + 0.5, i + 0.5)
            sh_basis_at(x, y, z, basis)
            for c in range(3):
                image[i, j, c] = max(sh_channel(basis, coeffs, n_k, c), 0.0)
            if bins:
                lo, hi, w = _profile_bin(x, y, z, up, bins)
                for c in range(3):
                    image[i, j, c] += (1.0 - w) * profile[lo, c] + w * profile[hi, c]
    return image


@numba.njit(parallel=True, cache=True)
def environment_backward(rotation, intrinsics, width, height, coeffs, up, profile, grad):
    """The gradients (K, 3) and (B, 3) float64 of the SH coefficients and the profile given the
    image's gradient ``grad`` (H, W, 3), for the arguments of :func:`environment_forward`."""
    n_k, bins = coeffs.shape[0], profile.shape[0]
    n_blocks = (height + ROW_BLOCK - 1) // ROW_BLOCK
    g_coeffs = np.zeros((n_blocks, n_k, 3))
    g_profile = np.zeros((n_blocks, bins, 3))
    for block in numba.prange(n_blocks):
        basis = np.empty(16)
        acc = np.zeros((n_k, 3))
        for i in range(block * ROW_BLOCK, min((block + 1) * ROW_BLOCK, height)):
            for j in range(width):
                x, y, z = _ray(rotation, intrinsics, j + 0.5, i + 0.5)
                sh_basis_at(x, y, z, basis)
                for c in range(3):
                    if (
                        sh_channel(basis, coeffs, n_k, c) >= 0.0
                    ):  # where the clamp at 0 is active, no gradient reaches the SH
                        g = grad[i, j, c]
                        for k in range(n_k):
                            acc[k, c] += basis[k] * g
                if bins:
                    lo, hi, w = _profile_bin(x, y, z, up, bins)
                    for c in range(3):
                        g_profile[block, lo, c] += (1.0 - w) * grad[i, j, c]
                        g_profile[block, hi, c] += w * grad[i, j, c]
        for k in range(n_k):  # element by element: a block copy compiles a shape check
            for c in range(3):
                g_coeffs[block, k, c] = acc[k, c]
    return g_coeffs.sum(0), g_profile.sum(0)


ENVIRONMENT_KERNELS = (environment_forward, environment_backward)


class _EnvironmentImage(torch.autograd.Function):
    @staticmethod
    def forward(ctx, coeffs, profile, up, rotation, intrinsics, width, height):
        args = (
            np.ascontiguousarray(rotation, np.float64),
            np.asarray(intrinsics, np.float64),
            width,
            height,
            np.ascontiguousarray(coeffs.detach().numpy(), np.float32),
            np.ascontiguousarray(up.detach().numpy(), np.float64),
            np.ascontiguousarray(profile.detach().numpy(), np.float32),
        )
        ctx.args = args
        return torch.from_numpy(environment_forward(*args))

    @staticmethod
    def backward(ctx, grad):
        g_coeffs, g_profile = environment_backward(*ctx.args, np.ascontiguousarray(grad.numpy(), np.float32))
        return torch.from_numpy(g_coeffs).float(), torch.from_numpy(g_profile).float(), None, None, None, None, None


def environment_image_cpu(
    coeffs: torch.Tensor,
    profile: torch.Tensor | None,
    up: torch.Tensor | None,
    camera: PinholeCamera,
    cam_from_world: torch.Tensor,
) -> torch.Tensor:
    """The background image (H, W, 3) of SH ``coeffs`` (K, 3) plus the elevation ``profile``
    (B, 3) about ``up`` (3,) (both None: SH alone) seen by one camera, for float32 CPU
    parameters; differentiable in ``coeffs`` and ``profile``."""
    rotation = torch.as_tensor(cam_from_world)[:3, :3].detach().cpu().double().numpy()
    intrinsics = (camera.fx, camera.fy, camera.cx, camera.cy)
    if profile is None:
        profile, up = coeffs.new_zeros(0, 3), coeffs.new_zeros(3)
    return _EnvironmentImage.apply(coeffs, profile, up, rotation, intrinsics, camera.width, camera.height)
