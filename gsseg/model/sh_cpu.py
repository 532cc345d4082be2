"""The Gaussians' SH colours on the CPU: numba kernels for :func:`gsseg.model.sh.eval_sh` with one
set of coefficients per direction, and its gradient with respect to the coefficients and
the directions (through which the colour's gradient reaches the Gaussians' positions).

One Gaussian at a time, computed in float64 and returned in float32, over Gaussians split
between threads (each writes its own rows); the tensor version is the reference the tests
compare with.
"""

from __future__ import annotations

import numba
import numpy as np
import torch

from gsseg.model.sh import C0, C1, C2, C3


@numba.njit(inline="always")
def sh_basis_at(x, y, z, out):
    """The 16 SH basis values at (x, y, z), in the order and signs of :func:`gsseg.model.sh.sh_basis`."""
    xx, yy, zz, xy, yz, xz = x * x, y * y, z * z, x * y, y * z, x * z
    out[0] = C0
    out[1], out[2], out[3] = -C1 * y, C1 * z, -C1 * x
    out[4], out[5], out[6] = C2[0] * xy, C2[1] * yz, C2[2] * (2 * zz - xx - yy)
    out[7], out[8] = C2[3] * xz, C2[4] * (xx - yy)
    out[9] = C3[0] * y * (3 * xx - yy)
    out[10] = C3[1] * xy * z
    out[11] = C3[2] * y * (4 * zz - xx - yy)
    out[12] = C3[3] * z * (2 * zz - 3 * xx - 3 * yy)
    out[13] = C3[4] * x * (4 * zz - xx - yy)
    out[14] = C3[5] * z * (xx - yy)
    out[15] = C3[6] * x * (xx - 3 * yy)


@numba.njit(inline="always")
def sh_channel(basis, coeffs, n_k, c):
    """Channel c of the SH colour before 3D-GS's clamp at 0: 0.5 + sum_k basis[k] coeffs[k, c]
    over the first ``n_k`` basis values, for coefficients (K, 3)."""
    s = 0.5
    for k in range(n_k):
        s += basis[k] * coeffs[k, c]
    return s


@numba.njit(inline="always")
def _basis_gradient(x, y, z, w, n_k):
    """sum_k w[k] grad B_k(x, y, z) over the first ``n_k`` basis functions: (dx, dy, dz)."""
    xx, yy, zz, xy, yz, xz = x * x, y * y, z * z, x * y, y * z, x * z
    dx = dy = dz = 0.0
    if n_k > 1:
        dx += -C1 * w[3]
        dy += -C1 * w[1]
        dz += C1 * w[2]
    if n_k > 4:
        dx += C2[0] * y * w[4] - 2 * C2[2] * x * w[6] + C2[3] * z * w[7] + 2 * C2[4] * x * w[8]
        dy += C2[0] * x * w[4] + C2[1] * z * w[5] - 2 * C2[2] * y * w[6] - 2 * C2[4] * y * w[8]
        dz += C2[1] * y * w[5] + 4 * C2[2] * z * w[6] + C2[3] * x * w[7]
    if n_k > 9:
        dx += (
            C3[0] * 6 * xy * w[9]
            + C3[1] * yz * w[10]
            - C3[2] * 2 * xy * w[11]
            - C3[3] * 6 * xz * w[12]
            + C3[4] * (4 * zz - 3 * xx - yy) * w[13]
            + C3[5] * 2 * xz * w[14]
            + C3[6] * 3 * (xx - yy) * w[15]
        )
        dy += (
            C3[0] * 3 * (xx - yy) * w[9]
            + C3[1] * xz * w[10]
            + C3[2] * (4 * zz - xx - 3 * yy) * w[11]
            - C3[3] * 6 * yz * w[12]
            - C3[4] * 2 * xy * w[13]
            - C3[5] * 2 * yz * w[14]
            - C3[6] * 6 * xy * w[15]
        )
        dz += (
            C3[1] * xy * w[10]
            + C3[2] * 8 * yz * w[11]
            + C3[3] * (6 * zz - 3 * xx - 3 * yy) * w[12]
            + C3[4] * 8 * xz * w[13]
            + C3[5] * (xx - yy) * w[14]
        )
    return dx, dy, dz


@numba.njit(parallel=True, cache=True)
def sh_forward(coeffs, dirs, n_k):
    """Colours (N, 3) float32 of coefficients (N, K, 3) along unit directions (N, 3) with the
    first ``n_k`` <= K basis functions, offset by 0.5 and clamped at 0."""
    n = dirs.shape[0]
    colours = np.empty((n, 3), np.float32)
    for i in numba.prange(n):
        basis = np.empty(16)
        sh_basis_at(dirs[i, 0], dirs[i, 1], dirs[i, 2], basis)
        for c in range(3):
            colours[i, c] = max(sh_channel(basis, coeffs[i], n_k, c), 0.0)
    return colours


@numba.njit(parallel=True, cache=True)
def sh_backward(coeffs, dirs, n_k, grad):
    """The gradients (N, K, 3) and (N, 3) float32 of a loss with respect to the coefficients
    and the directions of :func:`sh_forward`, given its gradient ``grad`` (N, 3)."""
    n = dirs.shape[0]
    g_coeffs = np.zeros(coeffs.shape, np.float32)
    g_dirs = np.empty((n, 3), np.float32)
    for i in numba.prange(n):
        basis, w = np.empty(16), np.zeros(16)
        x, y, z = dirs[i, 0], dirs[i, 1], dirs[i, 2]
        sh_basis_at(x, y, z, basis)
        for c in range(3):
            if sh_channel(basis, coeffs[i], n_k, c) >= 0.0:  # where the clamp at 0 is active, no gradient passes
                g = grad[i, c]
                for k in range(n_k):
                    g_coeffs[i, k, c] = basis[k] * g
                    w[k] += coeffs[i, k, c] * g
        g_dirs[i, 0], g_dirs[i, 1], g_dirs[i, 2] = _basis_gradient(x, y, z, w, n_k)
    return g_coeffs, g_dirs


SH_KERNELS = (sh_forward, sh_backward)


class _EvalSH(torch.autograd.Function):
    @staticmethod
    def forward(ctx, coeffs, dirs, n_k):
        ctx.arrays = tuple(np.ascontiguousarray(x.detach().numpy(), np.float32) for x in (coeffs, dirs))
        ctx.n_k = n_k
        return torch.from_numpy(sh_forward(*ctx.arrays, n_k))

    @staticmethod
    def backward(ctx, grad):
        g_coeffs, g_dirs = sh_backward(*ctx.arrays, ctx.n_k, np.ascontiguousarray(grad.numpy(), np.float32))
        return torch.from_numpy(g_coeffs), torch.from_numpy(g_dirs), None


def eval_sh_cpu(degree: int, coeffs: torch.Tensor, dirs: torch.Tensor) -> torch.Tensor:
    """:func:`gsseg.model.sh.eval_sh` for float32 CPU coefficients (N, K, 3) and unit directions
    (N, 3): (N, 3) colours, differentiable in both."""
    n_k = (degree + 1) ** 2
    if coeffs.shape[1] < n_k:
        raise ValueError(f"SH degree {degree} needs {n_k} coefficients per direction, not {coeffs.shape[1]}")
    return _EvalSH.apply(coeffs, dirs, n_k)
