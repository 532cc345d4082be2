"""The mean SSIM of the photometric loss on the CPU: numba kernels for it and its gradient.

The same SSIM as :func:`gsseg.train.losses.ssim_map`, the torch reference the tests compare
with: local means and (co)variances under an 11x11 Gaussian window of standard deviation 1.5,
reflect-padded. The images stay as they are rendered, (H, W, C) with the channels last, and
are filtered as rows of W * C values, in two separable passes:

- forward: the five moments (a, b, a^2, b^2, ab) filtered along the rows, then along the
  columns, where each pixel's SSIM and its derivatives with respect to the three moments that
  depend on ``a`` (mean, mean of squares, mean of products) are computed at once;
- backward: those derivatives filtered by the transposed filters (the column pass, then the
  row pass) and combined with ``a`` and ``b``.

A filter with reflect padding is a banded matrix; it is applied through a table of each
output's source indices and weights (:func:`reflect_taps`), and along a row the interior,
where the taps are the plain window, by shifted sums over contiguous memory, which LLVM
compiles to SIMD code. Rows are split over threads; every value is float32, row sums float64.
"""

from __future__ import annotations

import numba
import numpy as np
import torch

SSIM_WINDOW = 11  # 3D-GS's SSIM: an 11x11 Gaussian window of standard deviation 1.5
SSIM_SIGMA = 1.5
f32 = np.float32
C1, C2 = f32(0.01**2), f32(0.03**2)
_TWO = f32(2.0)
_FAST = {"reassoc", "contract", "nsz"}


def gaussian_window() -> np.ndarray:
    """(SSIM_WINDOW,) float32 normalised Gaussian weights."""
    t = np.arange(SSIM_WINDOW, dtype=np.float64) - SSIM_WINDOW // 2
    g = np.exp(-(t**2) / (2 * SSIM_SIGMA**2))
    return (g / g.sum()).astype(np.float32)


def reflect_taps(n: int, transpose: bool = False) -> tuple[np.ndarray, np.ndarray, int, int]:
    """The reflect-padded Gaussian filter of a line of ``n`` values (or its transpose) as a
    table: out[i] = sum_t weights[i, t] * in[index[i, t]].

    Returns:
        index (n, T) int64 and weights (n, T) float32 (unused entries weigh 0), and the range
        [lo, hi) of outputs whose taps are the plain window in[i - 5 .. i + 5] weighed by it.
    """
    if n <= SSIM_WINDOW // 2:
        raise ValueError(f"SSIM's reflect padding needs lines longer than {SSIM_WINDOW // 2} pixels, not {n}")
    g = gaussian_window()
    r = SSIM_WINDOW // 2
    out = np.repeat(np.arange(n), SSIM_WINDOW)
    src = out + np.tile(np.arange(SSIM_WINDOW) - r, n)
    src = np.where(src < 0, -src, np.where(src >= n, 2 * (n - 1) - src, src))
    w = np.tile(g, n)
    if transpose:
        out, src = src, out
    order = np.argsort(out, kind="stable")
    out, src, w = out[order], src[order], w[order]
    counts = np.bincount(out, minlength=n)
    slot = np.arange(len(out)) - np.repeat(np.cumsum(counts) - counts, counts)
    index = np.zeros((n, counts.max()), np.int64)
    weights = np.zeros((n, counts.max()), np.float32)
    index[out, slot], weights[out, slot] = src, w
    plain = (counts == SSIM_WINDOW) & (index[:, :SSIM_WINDOW] == np.arange(n)[:, None] + np.arange(-r, r + 1)).all(1)
    lo = r + 1 if transpose else r
    hi = n - lo
    if not plain[lo:hi].all():
        raise AssertionError("the interior of the SSIM filter is not the plain window")
    return index, weights, lo, hi


@numba.njit(fastmath=_FAST, cache=True)
def _filter_line(src, dst, index, weights, lo, hi, n_ch, g):
    """dst (W * C,) = the row filter of src (W * C,): shifted sums in [lo, hi), the table elsewhere."""
    r = g.shape[0] // 2
    dst[:] = 0.0
    for k in range(g.shape[0]):
        gk = g[k]
        shift = (k - r) * n_ch
        for j in range(lo * n_ch, hi * n_ch):
            dst[j] += gk * src[j + shift]
    for x in range(index.shape[0]):
        if lo <= x < hi:
            continue
        for t in range(index.shape[1]):
            w = weights[x, t]
            s = index[x, t] * n_ch
            for c in range(n_ch):
                dst[x * n_ch + c] += w * src[s + c]


@numba.njit(fastmath=_FAST, cache=True)
def _column_filter(src, row, index, weights, dst):
    """dst (L,) = sum_t weights[row, t] * src[index[row, t]] for src (H, L)."""
    dst[:] = 0.0
    for t in range(index.shape[1]):
        w = weights[row, t]
        if w == 0.0:
            continue
        s = src[index[row, t]]
        for j in range(dst.shape[0]):
            dst[j] += w * s[j]


@numba.njit(parallel=True, fastmath=_FAST, cache=True)
def ssim_forward(a, b, row_taps, col_taps, n_ch, g):
    """Mean-SSIM pass over images a, b given as (H, W * C) float32.

    Returns the sum of the SSIM map (float64) and its derivatives with respect to the local
    mean of a, of a^2 and of ab, each (H, W * C) float32.
    """
    h, length = a.shape
    r_index, r_weights, lo, hi = row_taps
    c_index, c_weights = col_taps
    rows = np.empty((5, h, length), np.float32)
    for y in numba.prange(h):
        products = np.empty((5, length), np.float32)
        for j in range(length):
            products[0, j] = a[y, j]
            products[1, j] = b[y, j]
            products[2, j] = a[y, j] * a[y, j]
            products[3, j] = b[y, j] * b[y, j]
            products[4, j] = a[y, j] * b[y, j]
        for q in range(5):
            _filter_line(products[q], rows[q, y], r_index, r_weights, lo, hi, n_ch, g)
    d_mu = np.empty((h, length), np.float32)
    d_aa = np.empty((h, length), np.float32)
    d_ab = np.empty((h, length), np.float32)
    sums = np.zeros(h, np.float64)
    for y in numba.prange(h):
        m = np.empty((5, length), np.float32)
        for q in range(5):
            _column_filter(rows[q], y, c_index, c_weights, m[q])
        total = 0.0
        for j in range(length):
            mu_a, mu_b = m[0, j], m[1, j]
            a1 = _TWO * mu_a * mu_b + C1
            a2 = _TWO * (m[4, j] - mu_a * mu_b) + C2
            b1 = mu_a * mu_a + mu_b * mu_b + C1
            b2 = (m[2, j] - mu_a * mu_a) + (m[3, j] - mu_b * mu_b) + C2
            inv = f32(1.0) / (b1 * b2)
            s = a1 * a2 * inv
            total += s
            d_mu[y, j] = _TWO * (mu_b * (a2 - a1) * inv - mu_a * s / b1 + mu_a * s / b2)
            d_aa[y, j] = -s / b2
            d_ab[y, j] = _TWO * a1 * inv
        sums[y] = total
    return sums.sum(), d_mu, d_aa, d_ab


@numba.njit(parallel=True, fastmath=_FAST, cache=True)
def ssim_backward(a, b, d_mu, d_aa, d_ab, row_taps_t, col_taps_t, n_ch, g, scale):
    """The gradient (H, W * C) float32 of ``scale`` times the SSIM map's sum with respect to a,
    from the derivatives :func:`ssim_forward` returns, through the transposed filters."""
    h, length = a.shape
    r_index, r_weights, lo, hi = row_taps_t
    c_index, c_weights = col_taps_t
    cols = np.empty((3, h, length), np.float32)
    for y in numba.prange(h):
        _column_filter(d_mu, y, c_index, c_weights, cols[0, y])
        _column_filter(d_aa, y, c_index, c_weights, cols[1, y])
        _column_filter(d_ab, y, c_index, c_weights, cols[2, y])
    grad = np.empty((h, length), np.float32)
    for y in numba.prange(h):
        u = np.empty((3, length), np.float32)
        for q in range(3):
            _filter_line(cols[q, y], u[q], r_index, r_weights, lo, hi, n_ch, g)
        for j in range(length):
            grad[y, j] = scale * (u[0, j] + _TWO * a[y, j] * u[1, j] + b[y, j] * u[2, j])
    return grad


SSIM_KERNELS = (ssim_forward, ssim_backward)  # the kernels of the loss and its gradient


class _MeanSSIM(torch.autograd.Function):
    @staticmethod
    def forward(ctx, rendered, target):
        h, w, c = rendered.shape
        a = np.ascontiguousarray(rendered.detach().numpy(), dtype=np.float32).reshape(h, w * c)
        b = np.ascontiguousarray(target.detach().numpy(), dtype=np.float32).reshape(h, w * c)
        g = gaussian_window()
        col_index, col_weights, _, _ = reflect_taps(h)
        total, d_mu, d_aa, d_ab = ssim_forward(a, b, reflect_taps(w), (col_index, col_weights), c, g)
        ctx.saved = (a, b, d_mu, d_aa, d_ab)
        ctx.shape, ctx.dtype = (h, w, c), rendered.dtype
        return torch.tensor(total / a.size, dtype=rendered.dtype)

    @staticmethod
    def backward(ctx, grad_out):
        a, b, d_mu, d_aa, d_ab = ctx.saved
        h, w, c = ctx.shape
        col_index, col_weights, _, _ = reflect_taps(h, transpose=True)
        rows_t = reflect_taps(w, transpose=True)
        scale = np.float32(float(grad_out) / a.size)
        grad = ssim_backward(a, b, d_mu, d_aa, d_ab, rows_t, (col_index, col_weights), c, gaussian_window(), scale)
        return torch.from_numpy(grad.reshape(h, w, c)).to(ctx.dtype), None


def mean_ssim_cpu(rendered: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """The mean over pixels and channels of the SSIM of two (H, W, C) CPU images in [0, 1],
    computed in float32; a scalar whose gradient reaches ``rendered`` (``target`` is a
    constant)."""
    return _MeanSSIM.apply(rendered, target)
