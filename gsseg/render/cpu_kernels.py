"""Numba kernels of the ``cpu`` backend: tile binning, front-to-back blending and its
reverse-order backward pass. Compiled on first use and cached; no compiler at install.

Scalars are computed in float64 and stored in float32. Work is split over tiles; the
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


@numba.njit(inline="always")
def _alpha_at(means2d, conics, opacities, min_power, g, px, py):
    """(alpha, gaussian value, power, dx, dy) of Gaussian g at pixel centre (px, py);
    alpha is 0 where the 3D-GS rules skip the Gaussian. ``min_power[g]`` = log(ALPHA_MIN /
    opacity) lets most skipped Gaussians be recognised before the exponential."""
    dx = means2d[g, 0] - px
    dy = means2d[g, 1] - py
    power = -0.5 * (conics[g, 0] * dx * dx + conics[g, 2] * dy * dy) - conics[g, 1] * dx * dy
    if power > 0.0 or power < min_power[g]:
        return 0.0, 0.0, power, dx, dy
    gauss = math.exp(power)
    alpha = min(ALPHA_MAX, opacities[g] * gauss)
    if alpha < ALPHA_MIN:
        return 0.0, gauss, power, dx, dy
    return alpha, gauss, power, dx, dy


@numba.njit(cache=True)
def _min_power(opacities):
    out = np.empty(opacities.shape[0], np.float64)
    for g in range(opacities.shape[0]):
        out[g] = math.log(ALPHA_MIN / opacities[g]) if opacities[g] > 0 else np.inf
    return out


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
    min_power = _min_power(opacities)
    for t in numba.prange(n_tiles):
        start, end = offsets[t], offsets[t + 1]
        if start == end:
            continue
        y0, x0 = (t // n_tiles_x) * tile, (t % n_tiles_x) * tile
        acc = np.empty(n_ch, np.float64)
        for y in range(y0, min(y0 + tile, height)):
            for x in range(x0, min(x0 + tile, width)):
                acc[:] = 0.0
                trans = 1.0
                last = 0
                for k in range(start, end):
                    g = ids[k]
                    alpha = _alpha_at(means2d, conics, opacities, min_power, g, x + 0.5, y + 0.5)[0]
                    if alpha == 0.0:
                        continue
                    next_t = trans * (1.0 - alpha)
                    if next_t < T_MIN:
                        break
                    w = alpha * trans
                    for ch in range(n_ch):
                        acc[ch] += w * features[g, ch]
                    trans = next_t
                    last = k - start + 1
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
    min_power = _min_power(opacities)
    for w_id in numba.prange(n_workers):
        for t in range(w_id, n_tiles, n_workers):
            start = offsets[t]
            y0, x0 = (t // n_tiles_x) * tile, (t % n_tiles_x) * tile
            for y in range(y0, min(y0 + tile, height)):
                for x in range(x0, min(x0 + tile, width)):
                    t_final = final_t[y, x]
                    trans = t_final
                    behind = 0.0  # (contributions behind the current Gaussian) . grad_image
                    d_alpha_out = grad_alpha[y, x]
                    for k in range(start + n_contrib[y, x] - 1, start - 1, -1):
                        g = ids[k]
                        alpha, gauss, power, dx, dy = _alpha_at(means2d, conics, opacities, min_power, g, x + 0.5, y + 0.5)
                        if alpha == 0.0:
                            continue
                        one_minus = 1.0 - alpha
                        trans = trans / one_minus
                        weight = alpha * trans
                        f_dot = 0.0
                        for ch in range(n_ch):
                            d_pix = grad_image[y, x, ch]
                            g_feat[w_id, g, ch] += weight * d_pix
                            f_dot += features[g, ch] * d_pix
                        d_alpha = d_alpha_out * t_final / one_minus + f_dot * trans - behind / one_minus
                        behind += weight * f_dot
                        if opacities[g] * gauss > ALPHA_MAX:
                            continue  # clamped: no gradient reaches opacity or shape
                        g_opac[w_id, g] += gauss * d_alpha
                        d_power = opacities[g] * gauss * d_alpha
                        a, b, c = conics[g, 0], conics[g, 1], conics[g, 2]
                        g_means[w_id, g, 0] += d_power * (-a * dx - b * dy)
                        g_means[w_id, g, 1] += d_power * (-c * dy - b * dx)
                        g_conics[w_id, g, 0] += -0.5 * dx * dx * d_power
                        g_conics[w_id, g, 1] += -dx * dy * d_power
                        g_conics[w_id, g, 2] += -0.5 * dy * dy * d_power
    return g_means.sum(0), g_conics.sum(0), g_opac.sum(0), g_feat.sum(0)
