"""Numba kernels of the ``cpu`` backend: tile binning, front-to-back blending and its
reverse-order backward pass. Compiled on first use and cached; no compiler at install.

A tile is processed the way the CUDA rasterizers process it, with its pixels as the lanes:
the kernels walk the tile's depth-sorted Gaussians and update all of its pixels at once, in
branch-free loops over pixels that LLVM compiles to SIMD code. Those loops

- use :func:`exp_f32`, a polynomial, because numba has no vector exponential without SVML;
- are separate (not inlined) functions, whose array arguments let LLVM bound the memory
  they touch, and run over unsigned indices, which numba does not wrap around: LLVM needs
  both to vectorise them;
- visit only the rows of the tile that the Gaussian's footprint reaches.

Channels that only some pixels need (the object features of the pixels a loss samples) are
blended at those pixels alone: each tile keeps the sorted list of its selected pixels, and
every Gaussian adds into the selected pixels of the rows it reaches.

Per-pixel values are float32, as on the GPU; per-Gaussian gradients are summed in float64.
Work is split over tiles; the backward pass gives every worker its own gradient buffer,
summed afterwards, so results do not depend on thread timing.
"""

from __future__ import annotations

import math
from pathlib import Path

import numba
import numpy as np

from gsseg.render.blend_rules import ALPHA_MAX, ALPHA_MIN, T_MIN

f32 = np.float32
# Below this power exp(power) < ALPHA_MIN, so no Gaussian (opacity <= 1) is blended there.
POWER_FLOOR = f32(-6.0)
_LN2, _INV_LN2 = f32(math.log(2.0)), f32(1.0 / math.log(2.0))
_C2, _C3, _C4, _C5, _C6 = (f32(1.0 / math.factorial(k)) for k in range(2, 7))
# Reduction loops may be reordered (and so vectorised); nothing assumes finite values.
_FAST = {"reassoc", "contract", "nsz"}


@numba.njit(cache=True)
def bin_gaussians(
    rects: np.ndarray, order: np.ndarray, n_tiles_x: int, n_tiles_y: int
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
def exp_f32(x):
    """exp(x) in float32 for x in [POWER_FLOOR, 0], as accurate as ``math.exp`` in float32
    (relative error < 3e-7): x = k ln 2 + r with |r| <= ln(2) / 2, a degree-6 Taylor
    polynomial for exp(r), and 2^k (k in -9..0) as a product of selected powers of two."""
    k = np.floor(x * _INV_LN2 + f32(0.5))
    r = x - k * _LN2
    p = f32(1.0) + r * (f32(1.0) + r * (_C2 + r * (_C3 + r * (_C4 + r * (_C5 + r * _C6)))))
    m = -np.int32(k)
    s = (
        (f32(0.5) if m & 1 else f32(1.0))
        * (f32(0.25) if m & 2 else f32(1.0))
        * (f32(1.0 / 16) if m & 4 else f32(1.0))
        * (f32(1.0 / 256) if m & 8 else f32(1.0))
    )
    return p * s


@numba.njit(cache=True)
def _gather_tile(ids, start, end, means2d, conics, opacities):
    """The tile's Gaussians as one contiguous (m, 6) float32 block: mean x, mean y, conic
    a, b, c, opacity."""
    loc = np.empty((end - start, 6), np.float32)
    for j in range(end - start):
        g = ids[start + j]
        loc[j, 0], loc[j, 1] = means2d[g, 0], means2d[g, 1]
        loc[j, 2], loc[j, 3], loc[j, 4] = conics[g, 0], conics[g, 1], conics[g, 2]
        loc[j, 5] = opacities[g]
    return loc


@numba.njit(cache=True)
def _gather_rows(ids, start, end, values):
    """values[ids[start:end]] as a contiguous block."""
    out = np.empty((end - start, values.shape[1]), values.dtype)
    for j in range(end - start):
        for c in range(values.shape[1]):  # element by element: a row copy compiles a shape check
            out[j, c] = values[ids[start + j], c]
    return out


@numba.njit(inline="always")
def _tile_pixels(t, n_tiles_x, tile, width, height, px, py, inside):
    """Fill the pixel centres px, py (P,) of tile t (P = tile^2, row-major) and whether
    each lies in the image; returns the tile's origin (x0, y0)."""
    x0, y0 = (t % n_tiles_x) * tile, (t // n_tiles_x) * tile
    for k in range(tile * tile):
        x, y = x0 + k % tile, y0 + k // tile
        px[k], py[k] = f32(x + 0.5), f32(y + 0.5)
        inside[k] = x < width and y < height
    return x0, y0


@numba.njit(inline="always")
def _pixel_span(loc, j, y0, tile, height):
    """The pixels [lo, hi) of a tile at y0 (row-major, P = tile^2) in the rows that the
    tile's j-th Gaussian can reach: those within the bounding box of its ellipse
    alpha >= ALPHA_MIN, padded by a row. Empty when its opacity is below ALPHA_MIN."""
    a, b, c, o = loc[j, 2], loc[j, 3], loc[j, 4], loc[j, 5]
    if o < ALPHA_MIN:
        return 0, 0
    det = a * c - b * b
    if not det > 0:
        return 0, tile * tile
    # alpha >= ALPHA_MIN  <=>  d^T conic d <= 2 log(o / ALPHA_MIN); the ellipse's half-height
    # is sqrt of that times the covariance's yy entry, a / det.
    half = math.sqrt(2.0 * math.log(o / ALPHA_MIN) * a / det) + 1.0
    rows = min(tile, height - y0)
    lo = int(min(max(math.floor(loc[j, 1] - half) - y0, 0.0), rows))
    hi = int(min(max(math.ceil(loc[j, 1] + half) - y0, 0.0), rows))
    return lo * tile, max(lo, hi) * tile


@numba.njit(cache=True, fastmath=_FAST, error_model="numpy")
def _alphas(loc, j, px, py, lo, hi, alpha, gauss):
    """alpha and gauss at pixels [lo, hi) of the tile for its j-th Gaussian, alpha = min(0.99,
    opacity * gauss) and 0 where the 3D-GS rules skip it. Returns how many pixels it reaches."""
    mx, my, a, b, c, o = loc[j, 0], loc[j, 1], loc[j, 2], loc[j, 3], loc[j, 4], loc[j, 5]
    hits = f32(0.0)
    for p in range(np.uint64(lo), np.uint64(hi)):
        dx, dy = mx - px[p], my - py[p]
        power = f32(-0.5) * (a * dx * dx + c * dy * dy) - b * dx * dy
        g = exp_f32(max(power, POWER_FLOOR))
        al = min(f32(ALPHA_MAX), o * g)
        ok = (power <= f32(0.0)) & (al >= f32(ALPHA_MIN))
        alpha[p] = al if ok else f32(0.0)
        gauss[p] = g
        hits += f32(1.0) if ok else f32(0.0)
    return hits


@numba.njit(inline="always")
def _reached(loc, j, y0, tile, height, px, py, alpha, gauss):
    """The pixels [lo, hi) of the tile that its j-th Gaussian can reach, with alpha and gauss
    filled there by :func:`_alphas`; lo == hi when it blends into none of them."""
    lo, hi = _pixel_span(loc, j, y0, tile, height)
    if lo == hi or _alphas(loc, j, px, py, lo, hi, alpha, gauss) == 0:
        return lo, lo
    return lo, hi


@numba.njit(cache=True, fastmath=_FAST, error_model="numpy")
def _blend_step(j, lo, hi, alpha, trans, live, weight, last):
    """Blend the tile's j-th Gaussian, with alpha from :func:`_alphas`, into the live pixels
    in [lo, hi): weight = alpha T, T *= 1 - alpha, unless that would take T below T_MIN,
    which ends the pixel (live = 0). last becomes j + 1 where it blends. Returns (pixels
    blended, pixels ended)."""
    blended = f32(0.0)
    ended = f32(0.0)
    for p in range(np.uint64(lo), np.uint64(hi)):
        al = alpha[p] * live[p]
        keep = f32(0.0) if trans[p] * (f32(1.0) - al) < f32(T_MIN) else f32(1.0)
        ended += live[p] * (f32(1.0) - keep)
        live[p] *= keep
        al *= keep
        weight[p] = al * trans[p]
        trans[p] = trans[p] * (f32(1.0) - al)
        last[p] = np.int32(j + 1) if al > f32(0.0) else last[p]
        blended += f32(1.0) if al > f32(0.0) else f32(0.0)
    return blended, ended


@numba.njit(cache=True, fastmath=_FAST, error_model="numpy")
def _add_weighted(acc, feat, j, weight, lo, hi):
    """acc[:, p] += weight[p] * feat[j] for the pixels p in [lo, hi); acc is (C, P)."""
    for ch in range(acc.shape[0]):
        f = feat[j, ch]
        row = acc[ch]
        for p in range(np.uint64(lo), np.uint64(hi)):
            row[p] += weight[p] * f


@numba.njit(inline="always")
def _selected_rows(sel_offsets, sel_lanes, t, tile, row_start):
    """Fill row_start (tile + 1,): row_start[r] is the first entry of tile t's selected pixels
    (sel_lanes[sel_offsets[t]:sel_offsets[t + 1]], sorted pixel indices within the tile) in
    row r or below, so that the selected pixels in [lo, hi) are the entries
    [row_start[lo // tile], row_start[hi // tile])."""
    q, end = sel_offsets[t], sel_offsets[t + 1]
    for r in range(tile + 1):
        while q < end and sel_lanes[q] < r * tile:
            q += 1
        row_start[r] = q


@numba.njit(cache=True, fastmath=_FAST, error_model="numpy")
def _add_weighted_at(out, feat, g, weight, sel_lanes, q_lo, q_hi):
    """out[q] += weight[sel_lanes[q]] * feat[g] for the selected pixels q in [q_lo, q_hi);
    out is (M, E)."""
    for q in range(q_lo, q_hi):
        w = weight[sel_lanes[q]]
        for ch in range(np.uint64(out.shape[1])):
            out[q, ch] += w * feat[g, ch]


@numba.njit(cache=True, fastmath=_FAST, error_model="numpy")
def _unblend_step(j, lo, hi, n_last, alpha, trans, weight):
    """The backward pass's step to the tile's j-th Gaussian: keep alpha where the pixel's
    forward pass blended entry j (j < n_last), recover T before it by division and set
    weight = alpha T. Returns how many pixels it blended."""
    active = f32(0.0)
    for p in range(np.uint64(lo), np.uint64(hi)):
        al = alpha[p] if j < n_last[p] else f32(0.0)
        alpha[p] = al
        trans[p] = trans[p] / (f32(1.0) - al)
        weight[p] = al * trans[p]
        active += f32(1.0) if al > f32(0.0) else f32(0.0)
    return active


@numba.njit(cache=True, fastmath=_FAST, error_model="numpy")
def _feature_grads(feat, j, d_pix, weight, lo, hi, f_dot, tg, n_geo):
    """Gradient of the tile's j-th Gaussian's features, tg[j, 6 + ch] += sum_p weight[p]
    d_pix[ch, p], and f_dot[p] = feat[j, :n_geo] . d_pix[:n_geo, p] over the pixels in
    [lo, hi): only the first ``n_geo`` channels pass their gradient on to the geometry."""
    f_dot[lo:hi] = 0.0
    for ch in range(d_pix.shape[0]):
        f = feat[j, ch]
        d_row = d_pix[ch]
        s = f32(0.0)
        if ch < n_geo:
            for p in range(np.uint64(lo), np.uint64(hi)):
                f_dot[p] += f * d_row[p]
                s += weight[p] * d_row[p]
        else:
            for p in range(np.uint64(lo), np.uint64(hi)):
                s += weight[p] * d_row[p]
        tg[j, 6 + ch] += s


@numba.njit(cache=True, fastmath=_FAST, error_model="numpy")
def _feature_grads_at(j, weight, sel_lanes, q_lo, q_hi, d_sel, tg, col, sums):
    """Gradient of the tile's j-th Gaussian's selected-pixel features: tg[j, col + ch] +=
    sum_q weight[sel_lanes[q]] d_sel[q, ch] over the selected pixels q in [q_lo, q_hi),
    summed in ``sums`` (E,) float32."""
    sums[:] = 0.0
    for q in range(q_lo, q_hi):
        w = weight[sel_lanes[q]]
        for ch in range(np.uint64(sums.shape[0])):
            sums[ch] += w * d_sel[q, ch]
    for ch in range(sums.shape[0]):
        tg[j, col + ch] += sums[ch]


@numba.njit(cache=True, fastmath=_FAST, error_model="numpy")
def _shape_grads(loc, j, px, py, lo, hi, alpha, gauss, trans, weight, f_dot, behind, d_out, tg):
    """Gradients of the tile's j-th Gaussian's mean, conic and opacity, summed over the
    pixels in [lo, hi) into tg[j, :6], through dL/dalpha, which needs the blended colour
    behind the Gaussian (``behind``, updated here) and d_out = dL/dalpha_pixel * T_final."""
    mx, my, a, b, c, o = loc[j, 0], loc[j, 1], loc[j, 2], loc[j, 3], loc[j, 4], loc[j, 5]
    s_mx = s_my = s_a = s_b = s_c = s_o = f32(0.0)
    for p in range(np.uint64(lo), np.uint64(hi)):
        one_minus = f32(1.0) - alpha[p]
        d_alpha = (d_out[p] - behind[p]) / one_minus + f_dot[p] * trans[p]
        behind[p] += weight[p] * f_dot[p]
        og = o * gauss[p]
        # Where the 0.99 clamp is active, no gradient reaches opacity or shape.
        free = (alpha[p] > f32(0.0)) & (og <= f32(ALPHA_MAX))
        d_power = og * d_alpha if free else f32(0.0)
        dx, dy = mx - px[p], my - py[p]
        s_mx += d_power * (-a * dx - b * dy)
        s_my += d_power * (-c * dy - b * dx)
        s_a += f32(-0.5) * dx * dx * d_power
        s_b += -dx * dy * d_power
        s_c += f32(-0.5) * dy * dy * d_power
        s_o += gauss[p] * d_alpha if free else f32(0.0)
    tg[j, 0] += s_mx
    tg[j, 1] += s_my
    tg[j, 2] += s_a
    tg[j, 3] += s_b
    tg[j, 4] += s_c
    tg[j, 5] += s_o


@numba.njit(parallel=True, cache=True)
def blend_forward(
    means2d, conics, opacities, features, sel_features, offsets, ids, sel_offsets, sel_lanes, width, height, tile
):
    """Blend every tile: ``features`` (N, C) at every pixel, ``sel_features`` (N, E) at the
    selected pixels alone (tile t's are sel_lanes[sel_offsets[t]:sel_offsets[t + 1]], its
    pixel indices in row-major order, sorted). Returns image (H, W, C) float32, final
    transmittance (H, W) float32, n_contrib (H, W) int32 (how many entries of the tile
    list the pixel went through up to its last blended Gaussian) and the selected pixels'
    blend of ``sel_features`` (M, E) float32, in the order of ``sel_lanes``."""
    n_ch = features.shape[1]
    n_tiles_x = (width + tile - 1) // tile
    n_tiles = offsets.shape[0] - 1
    n_pix = tile * tile
    image = np.zeros((height, width, n_ch), np.float32)
    final_t = np.ones((height, width), np.float32)
    n_contrib = np.zeros((height, width), np.int32)
    sel_image = np.zeros((sel_lanes.shape[0], sel_features.shape[1]), np.float32)
    for t in numba.prange(n_tiles):
        start, end = offsets[t], offsets[t + 1]
        if start == end:
            continue
        loc = _gather_tile(ids, start, end, means2d, conics, opacities)
        feat = _gather_rows(ids, start, end, features)
        row_start = np.empty(tile + 1, np.int64)
        _selected_rows(sel_offsets, sel_lanes, t, tile, row_start)
        px, py = np.empty(n_pix, np.float32), np.empty(n_pix, np.float32)
        inside = np.empty(n_pix, np.bool_)
        x0, y0 = _tile_pixels(t, n_tiles_x, tile, width, height, px, py, inside)
        alpha, gauss, weight = np.empty(n_pix, np.float32), np.empty(n_pix, np.float32), np.empty(n_pix, np.float32)
        trans = np.ones(n_pix, np.float32)
        live = inside.astype(np.float32)
        last = np.zeros(n_pix, np.int32)
        acc = np.zeros((n_ch, n_pix), np.float32)
        n_live = live.sum()
        for j in range(end - start):
            lo, hi = _reached(loc, j, y0, tile, height, px, py, alpha, gauss)
            if lo == hi:
                continue
            blended, ended = _blend_step(j, lo, hi, alpha, trans, live, weight, last)
            if blended > 0:
                _add_weighted(acc, feat, j, weight, lo, hi)
                q_lo, q_hi = row_start[lo // tile], row_start[hi // tile]
                if q_lo < q_hi:
                    _add_weighted_at(sel_image, sel_features, ids[start + j], weight, sel_lanes, q_lo, q_hi)
            n_live -= ended
            if n_live == 0:
                break
        for p in range(n_pix):
            if inside[p]:
                y, x = y0 + p // tile, x0 + p % tile
                for ch in range(n_ch):
                    image[y, x, ch] = acc[ch, p]
                final_t[y, x] = trans[p]
                n_contrib[y, x] = last[p]
    return image, final_t, n_contrib, sel_image


@numba.njit(parallel=True, cache=True)
def blend_backward(
    means2d,
    conics,
    opacities,
    features,
    sel_features,
    offsets,
    ids,
    sel_offsets,
    sel_lanes,
    width,
    height,
    tile,
    final_t,
    n_contrib,
    grad_image,
    grad_alpha,
    grad_sel,
    n_geo,
    n_workers,
):
    """Gradients of a loss with respect to means2d (N, 2), conics (N, 3), opacities (N,),
    features (N, C) and sel_features (N, E), given its gradients grad_image (H, W, C),
    grad_alpha (H, W) and grad_sel (M, E) (the selected pixels' of :func:`blend_forward`).
    Only the first ``n_geo`` channels' gradients reach means2d, conics and opacities (the
    others', and those of ``sel_features``, reach their features alone, as if blended over
    the geometry detached).

    Walks each tile's list back to front, recovering every pixel's transmittance by
    division as the 3D-GS backward pass does. Worker w handles tiles w, w + n_workers, ...
    """
    n = means2d.shape[0]
    n_ch, n_sel_ch = features.shape[1], sel_features.shape[1]
    n_tiles_x = (width + tile - 1) // tile
    n_tiles = offsets.shape[0] - 1
    n_pix = tile * tile
    g_means = np.zeros((n_workers, n, 2), np.float64)
    g_conics = np.zeros((n_workers, n, 3), np.float64)
    g_opac = np.zeros((n_workers, n), np.float64)
    g_feat = np.zeros((n_workers, n, n_ch), np.float64)
    g_sel = np.zeros((n_workers, n, n_sel_ch), np.float64)
    for w_id in numba.prange(n_workers):
        px, py = np.empty(n_pix, np.float32), np.empty(n_pix, np.float32)
        inside = np.empty(n_pix, np.bool_)
        alpha, gauss, trans = np.empty(n_pix, np.float32), np.empty(n_pix, np.float32), np.empty(n_pix, np.float32)
        weight, f_dot = np.empty(n_pix, np.float32), np.empty(n_pix, np.float32)
        behind, d_out = np.empty(n_pix, np.float32), np.empty(n_pix, np.float32)
        n_last = np.empty(n_pix, np.int32)
        d_pix = np.empty((n_ch, n_pix), np.float32)
        row_start = np.empty(tile + 1, np.int64)
        sel_sums = np.empty(n_sel_ch, np.float32)
        for t in range(w_id, n_tiles, n_workers):
            start, end = offsets[t], offsets[t + 1]
            if start == end:
                continue
            loc = _gather_tile(ids, start, end, means2d, conics, opacities)
            feat = _gather_rows(ids, start, end, features)
            x0, y0 = _tile_pixels(t, n_tiles_x, tile, width, height, px, py, inside)
            _selected_rows(sel_offsets, sel_lanes, t, tile, row_start)
            n_max = 0
            for p in range(n_pix):
                y, x = min(y0 + p // tile, height - 1), min(x0 + p % tile, width - 1)
                n_last[p] = n_contrib[y, x] if inside[p] else 0
                trans[p] = final_t[y, x]
                d_out[p] = grad_alpha[y, x] * final_t[y, x]
                for ch in range(n_ch):
                    d_pix[ch, p] = grad_image[y, x, ch]
                n_max = max(n_max, n_last[p])
            behind[:] = 0.0
            # Tile-local gradients: mean x, y, conic a, b, c, opacity, the features, then
            # the selected pixels' features.
            tg = np.zeros((end - start, 6 + n_ch + n_sel_ch), np.float64)
            for j in range(n_max - 1, -1, -1):
                lo, hi = _reached(loc, j, y0, tile, height, px, py, alpha, gauss)
                if lo == hi:
                    continue
                if _unblend_step(j, lo, hi, n_last, alpha, trans, weight) == 0:
                    continue
                _feature_grads(feat, j, d_pix, weight, lo, hi, f_dot, tg, n_geo)
                q_lo, q_hi = row_start[lo // tile], row_start[hi // tile]
                if q_lo < q_hi:
                    _feature_grads_at(j, weight, sel_lanes, q_lo, q_hi, grad_sel, tg, 6 + n_ch, sel_sums)
                _shape_grads(loc, j, px, py, lo, hi, alpha, gauss, trans, weight, f_dot, behind, d_out, tg)
            for j in range(end - start):
                g = ids[start + j]
                g_means[w_id, g, 0] += tg[j, 0]
                g_means[w_id, g, 1] += tg[j, 1]
                for i in range(3):
                    g_conics[w_id, g, i] += tg[j, 2 + i]
                g_opac[w_id, g] += tg[j, 5]
                for ch in range(n_ch):
                    g_feat[w_id, g, ch] += tg[j, 6 + ch]
                for ch in range(n_sel_ch):
                    g_sel[w_id, g, ch] += tg[j, 6 + n_ch + ch]
    return g_means.sum(0), g_conics.sum(0), g_opac.sum(0), g_feat.sum(0), g_sel.sum(0)


@numba.njit(parallel=True, cache=True)
def accumulate_weights(means2d, conics, opacities, offsets, ids, width, height, tile, rows, n_rows, n_workers):
    """Blending weights summed per Gaussian and pixel class: out[r, g] = sum over the pixels
    with rows[y, x] == r of alpha_g T_g (rows < 0 are ignored). One forward pass, no colour.

    Returns (n_rows, N) float32. Each worker sums into its own (n_rows, N) buffer.
    """
    n = means2d.shape[0]
    n_tiles_x = (width + tile - 1) // tile
    n_tiles = offsets.shape[0] - 1
    n_pix = tile * tile
    buffers = np.zeros((n_workers, n_rows, n), np.float32)
    for w_id in numba.prange(n_workers):
        px, py = np.empty(n_pix, np.float32), np.empty(n_pix, np.float32)
        inside = np.empty(n_pix, np.bool_)
        alpha, gauss, weight = np.empty(n_pix, np.float32), np.empty(n_pix, np.float32), np.empty(n_pix, np.float32)
        trans, live = np.empty(n_pix, np.float32), np.empty(n_pix, np.float32)
        last = np.empty(n_pix, np.int32)
        row = np.empty(n_pix, np.int64)
        for t in range(w_id, n_tiles, n_workers):
            start, end = offsets[t], offsets[t + 1]
            if start == end:
                continue
            loc = _gather_tile(ids, start, end, means2d, conics, opacities)
            x0, y0 = _tile_pixels(t, n_tiles_x, tile, width, height, px, py, inside)
            for p in range(n_pix):
                y, x = min(y0 + p // tile, height - 1), min(x0 + p % tile, width - 1)
                row[p] = rows[y, x]
                live[p] = f32(1.0) if inside[p] and row[p] >= 0 else f32(0.0)
            n_live = live.sum()
            trans[:] = 1.0
            local = np.zeros((end - start, n_rows), np.float64)
            for j in range(end - start):
                if n_live == 0:
                    break
                lo, hi = _reached(loc, j, y0, tile, height, px, py, alpha, gauss)
                if lo == hi:
                    continue
                blended, ended = _blend_step(j, lo, hi, alpha, trans, live, weight, last)
                n_live -= ended
                if blended > 0:
                    for p in range(lo, hi):
                        if weight[p] > 0:
                            local[j, row[p]] += weight[p]
            for j in range(end - start):
                g = ids[start + j]
                for r in range(n_rows):
                    buffers[w_id, r, g] += local[j, r]
    out = buffers[0].copy()
    for w_id in range(1, n_workers):
        out += buffers[w_id]
    return out


STEP_KERNELS = (bin_gaussians, blend_forward, blend_backward)  # the kernels of a render and its backward pass


def compiled_on_disk(kernels: tuple = STEP_KERNELS) -> bool:
    """Whether numba's cache on disk holds ``kernels`` (numba functions compiled with
    ``cache=True``), so that their first call in a process loads them instead of compiling
    them. True when numba's cache cannot be inspected."""
    try:
        return all(k.signatures or Path(k._cache._cache_file._index_path).is_file() for k in kernels)
    except AttributeError:  # another numba's internals
        return True
