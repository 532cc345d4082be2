"""Numba kernels of the ``cpu`` backend: tile binning, front-to-back blending and its
reverse-order backward pass. Compiled on first use and cached; no compiler at install.

Per-pixel Gaussian values are computed in float32, as the CUDA rasterizers do; colour and
transmittance accumulate in float64. Work is split over tiles; the
backward pass gives every worker its own gradient buffer, summed afterwards, so results
do not depend on thread timing.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from gsseg.render.blend_rules import ALPHA_MAX, ALPHA_MIN, T_MIN


@numba.njit(cache=True)
def bin_gaussians(rects: np.ndarray, order: np.ndarray, n_tiles_x: int, n_tiles_y: int
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Lists of Gaussians per tile, front to back.

    Args:
        rects: (N, 4) int32 tile ranges [x0, y0, x1, y1). order: (N,) Gaussians sorted by depth.

    Returns:
        offsets (T + 1,) int64 and ids (M,) int64: tile t holds ids[offsets[t]:offsets[t + 1]].
    """
    n_tiles = n_tiles_x * n_tiles_y
    offsets = np.zeros(n_tiles + 1, np.int64)
    for g in range(rects.shape[0]):
        for ty in range(rects[g, 1], rects[g, 3]):
            for tx in range(rects[g, 0], rects[g, 2]):
                offsets[ty * n_tiles_x + tx + 1] += 1
    for t in range(n_tiles):
        offsets[t + 1] += offsets[t]
    cursor = offsets[:-1].copy()
    ids = np.empty(offsets[-1], np.int64)
    for g in order:
        for ty in range(rects[g, 1], rects[g, 3]):
            for tx in range(rects[g, 0], rects[g, 2]):
                t = ty * n_tiles_x + tx
                ids[cursor[t]] = g
                cursor[t] += 1
    return offsets, ids


@numba.njit(cache=True)
def _gather_tile(ids, start, end, means2d, conics, opacities):
    """The tile's Gaussians as one contiguous (m, 7) float32 block: mean x, mean y, conic
    a, b, c, opacity, and log(ALPHA_MIN / opacity), the power below which a Gaussian is skipped
    (so most skips need no exponential)."""
    loc = np.empty((end - start, 7), np.float32)
    for j in range(end - start):
        g = ids[start + j]
        loc[j, 0], loc[j, 1] = means2d[g, 0], means2d[g, 1]
        loc[j, 2], loc[j, 3], loc[j, 4] = conics[g, 0], conics[g, 1], conics[g, 2]
        loc[j, 5] = opacities[g]
        loc[j, 6] = math.log(ALPHA_MIN / opacities[g]) if opacities[g] > 0 else np.inf
    return loc


@numba.njit(cache=True)
def _gather_rows(ids, start, end, values):
    """values[ids[start:end]] as a contiguous block."""
    out = np.empty((end - start, values.shape[1]), values.dtype)
    for j in range(end - start):
        out[j] = values[ids[start + j]]
    return out


@numba.njit(inline="always")
def _alpha_at(loc, j, px, py):
    """(alpha, gaussian value, dx, dy) of the tile's j-th Gaussian at pixel centre (px, py);
    alpha is 0 where the 3D-GS rules skip the Gaussian."""
    dx = loc[j, 0] - px
    dy = loc[j, 1] - py
    power = np.float32(-0.5) * (loc[j, 2] * dx * dx + loc[j, 4] * dy * dy) - loc[j, 3] * dx * dy
    if power > 0 or power < loc[j, 6]:
        return np.float32(0), np.float32(0), dx, dy
    gauss = np.float32(math.exp(power))
    alpha = min(np.float32(ALPHA_MAX), loc[j, 5] * gauss)
    if alpha < np.float32(ALPHA_MIN):
        return np.float32(0), gauss, dx, dy
    return alpha, gauss, dx, dy


@numba.njit(inline="always")
def _pixel_weights(loc, px, py, weights):
    """Front-to-back blending weights alpha_j T_j of the tile's Gaussians at one pixel, with
    the 3D-GS rules. Fills weights[:last] (0 where a Gaussian is skipped) and returns
    (final transmittance, last), ``last`` being one past the last blended entry."""
    trans = 1.0
    last = 0
    for j in range(loc.shape[0]):
        alpha = _alpha_at(loc, j, px, py)[0]
        weights[j] = 0.0
        if alpha == 0:
            continue
        next_t = trans * (1.0 - alpha)
        if next_t < T_MIN:
            break
        weights[j] = alpha * trans
        trans = next_t
        last = j + 1
    return trans, last


@numba.njit(parallel=True, cache=True)
def blend_forward(means2d, conics, opacities, features, offsets, ids, width, height, tile):
    """Blend every tile. Returns image (H, W, C) float32, final transmittance (H, W) float64
    and n_contrib (H, W) int32: how many entries of the tile list the pixel went through
    up to its last blended Gaussian."""
    n_ch = features.shape[1]
    n_tiles_x = (width + tile - 1) // tile
    n_tiles = offsets.shape[0] - 1
    image = np.zeros((height, width, n_ch), np.float32)
    final_t = np.ones((height, width), np.float64)
    n_contrib = np.zeros((height, width), np.int32)
    for t in numba.prange(n_tiles):
        start, end = offsets[t], offsets[t + 1]
        if start == end:
            continue
        loc = _gather_tile(ids, start, end, means2d, conics, opacities)
        feat = _gather_rows(ids, start, end, features)
        y0, x0 = (t // n_tiles_x) * tile, (t % n_tiles_x) * tile
        acc = np.empty(n_ch, np.float64)
        weights = np.empty(end - start, np.float64)
        for y in range(y0, min(y0 + tile, height)):
            for x in range(x0, min(x0 + tile, width)):
                trans, last = _pixel_weights(loc, np.float32(x + 0.5), np.float32(y + 0.5), weights)
                acc[:] = 0.0
                for j in range(last):
                    w = weights[j]
                    if w != 0.0:
                        for ch in range(n_ch):
                            acc[ch] += w * feat[j, ch]
                for ch in range(n_ch):
                    image[y, x, ch] = acc[ch]
                final_t[y, x] = trans
                n_contrib[y, x] = last
    return image, final_t, n_contrib


@numba.njit(parallel=True, cache=True)
def blend_backward(means2d, conics, opacities, features, offsets, ids, width, height, tile,
                   final_t, n_contrib, grad_image, grad_alpha, n_workers):
    """Gradients of a loss with respect to means2d (N, 2), conics (N, 3), opacities (N,)
    and features (N, C), given its gradients grad_image (H, W, C) and grad_alpha (H, W).

    Walks each pixel's list back to front, recovering transmittance by division as the
    3D-GS backward pass does. Worker w handles tiles w, w + n_workers, ...
    """
    n = means2d.shape[0]
    n_ch = features.shape[1]
    n_tiles_x = (width + tile - 1) // tile
    n_tiles = offsets.shape[0] - 1
    g_means = np.zeros((n_workers, n, 2), np.float64)
    g_conics = np.zeros((n_workers, n, 3), np.float64)
    g_opac = np.zeros((n_workers, n), np.float64)
    g_feat = np.zeros((n_workers, n, n_ch), np.float64)
    for w_id in numba.prange(n_workers):
        d_pix = np.empty(n_ch, np.float64)
        for t in range(w_id, n_tiles, n_workers):
            start, end = offsets[t], offsets[t + 1]
            if start == end:
                continue
            loc = _gather_tile(ids, start, end, means2d, conics, opacities)
            feat = _gather_rows(ids, start, end, features)
            # Tile-local gradients: mean x, y, conic a, b, c, opacity, then the features.
            tg = np.zeros((end - start, 6 + n_ch), np.float64)
            y0, x0 = (t // n_tiles_x) * tile, (t % n_tiles_x) * tile
            for y in range(y0, min(y0 + tile, height)):
                for x in range(x0, min(x0 + tile, width)):
                    t_final = final_t[y, x]
                    trans = t_final
                    behind = 0.0  # (contributions behind the current Gaussian) . grad_image
                    d_alpha_out = grad_alpha[y, x]
                    px, py = np.float32(x + 0.5), np.float32(y + 0.5)
                    for ch in range(n_ch):
                        d_pix[ch] = grad_image[y, x, ch]
                    for j in range(n_contrib[y, x] - 1, -1, -1):
                        alpha, gauss, dx, dy = _alpha_at(loc, j, px, py)
                        if alpha == 0:
                            continue
                        one_minus = 1.0 - alpha
                        trans = trans / one_minus
                        weight = alpha * trans
                        f_dot = 0.0
                        for ch in range(n_ch):
                            tg[j, 6 + ch] += weight * d_pix[ch]
                            f_dot += feat[j, ch] * d_pix[ch]
                        d_alpha = d_alpha_out * t_final / one_minus + f_dot * trans - behind / one_minus
                        behind += weight * f_dot
                        if loc[j, 5] * gauss > ALPHA_MAX:
                            continue  # clamped: no gradient reaches opacity or shape
                        d_power = loc[j, 5] * gauss * d_alpha
                        a, b, c = loc[j, 2], loc[j, 3], loc[j, 4]
                        tg[j, 0] += d_power * (-a * dx - b * dy)
                        tg[j, 1] += d_power * (-c * dy - b * dx)
                        tg[j, 2] += -0.5 * dx * dx * d_power
                        tg[j, 3] += -dx * dy * d_power
                        tg[j, 4] += -0.5 * dy * dy * d_power
                        tg[j, 5] += gauss * d_alpha
            for j in range(end - start):
                g = ids[start + j]
                g_means[w_id, g, 0] += tg[j, 0]
                g_means[w_id, g, 1] += tg[j, 1]
                for i in range(3):
                    g_conics[w_id, g, i] += tg[j, 2 + i]
                g_opac[w_id, g] += tg[j, 5]
                for ch in range(n_ch):
                    g_feat[w_id, g, ch] += tg[j, 6 + ch]
    return g_means.sum(0), g_conics.sum(0), g_opac.sum(0), g_feat.sum(0)


@numba.njit(parallel=True, cache=True)
def accumulate_weights(means2d, conics, opacities, offsets, ids, width, height, tile, rows, n_rows,
                       n_workers):
    """Blending weights summed per Gaussian and pixel class: out[r, g] = sum over the pixels
    with rows[y, x] == r of alpha_g T_g (rows < 0 are ignored). One forward pass, no colour.

    Returns (n_rows, N) float32. Each worker sums into its own (n_rows, N) buffer.
    """
    n = means2d.shape[0]
    n_tiles_x = (width + tile - 1) // tile
    n_tiles = offsets.shape[0] - 1
    buffers = np.zeros((n_workers, n_rows, n), np.float32)
    for w_id in numba.prange(n_workers):
        for t in range(w_id, n_tiles, n_workers):
            start, end = offsets[t], offsets[t + 1]
            if start == end:
                continue
            loc = _gather_tile(ids, start, end, means2d, conics, opacities)
            local = np.zeros((end - start, n_rows), np.float64)
            weights = np.empty(end - start, np.float64)
            y0, x0 = (t // n_tiles_x) * tile, (t % n_tiles_x) * tile
            for y in range(y0, min(y0 + tile, height)):
                for x in range(x0, min(x0 + tile, width)):
                    r = rows[y, x]
                    if r < 0:
                        continue
                    last = _pixel_weights(loc, np.float32(x + 0.5), np.float32(y + 0.5), weights)[1]
                    for j in range(last):
                        local[j, r] += weights[j]
            for j in range(end - start):
                g = ids[start + j]
                for r in range(n_rows):
                    buffers[w_id, r, g] += local[j, r]
    out = buffers[0].copy()
    for w_id in range(1, n_workers):
        out += buffers[w_id]
    return out
