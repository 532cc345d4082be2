"""The ``cpu`` backend: the numba kernels behind a ``torch.autograd.Function``."""

from __future__ import annotations

import numba
import numpy as np
import torch

from gsseg.render import cpu_kernels
from gsseg.render.projection import TILE_SIZE, tile_rects


def as_float32_array(x: torch.Tensor) -> np.ndarray:
    """A contiguous float32 numpy copy (or view) of a tensor, as the kernels take it."""
    return np.ascontiguousarray(x.detach().cpu().numpy(), dtype=np.float32)


def bin_tiles(
    means2d: torch.Tensor, radii: torch.Tensor, depths: torch.Tensor, width: int, height: int
) -> tuple[np.ndarray, np.ndarray]:
    """Per-tile Gaussian lists sorted front to back: offsets (T + 1,), ids (M,)."""
    rects = tile_rects(means2d, radii, width, height).numpy()
    order = np.argsort(depths.detach().cpu().numpy(), kind="stable")
    return cpu_kernels.bin_gaussians(rects, order, -(-width // TILE_SIZE), -(-height // TILE_SIZE))


def select_pixels(
    pixels: torch.Tensor | None, width: int, height: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """The kernels' form of a pixel selection: flat indices ``pixels`` (P,) (y W + x, in any
    order, repeats allowed) as sorted per-tile lists. Returns sel_offsets (T + 1,) int64,
    sel_lanes (P,) int64 (each pixel's index within its tile) and order (P,) int64: entry q of
    the lists is ``pixels[order[q]]``; no pixel and order None when ``pixels`` is None."""
    n_tiles = -(-width // TILE_SIZE) * -(-height // TILE_SIZE)
    if pixels is None:
        return np.zeros(n_tiles + 1, np.int64), np.zeros(0, np.int64), None
    flat = pixels.detach().cpu().numpy().astype(np.int64)
    if flat.size and (flat.min() < 0 or flat.max() >= width * height):
        raise ValueError(f"pixel indices must lie in [0, {width * height}) for a {width}x{height} image")
    y, x = np.divmod(flat, width)
    tiles = (y // TILE_SIZE) * -(-width // TILE_SIZE) + x // TILE_SIZE
    lanes = (y % TILE_SIZE) * TILE_SIZE + x % TILE_SIZE
    order = np.lexsort((lanes, tiles))
    offsets = np.concatenate([[0], np.cumsum(np.bincount(tiles, minlength=n_tiles))]).astype(np.int64)
    return offsets, lanes[order], order


class _BlendCPU(torch.autograd.Function):
    @staticmethod
    def forward(ctx, means2d, conics, opacities, features, beside, depths, radii, width, height, pixels):
        arrays = [as_float32_array(x) for x in (means2d, conics, opacities)]
        c, e = features.shape[1], beside.shape[1]
        *selection, order = select_pixels(pixels, width, height)
        if order is None:  # ``beside`` blended at every pixel, after ``features``
            dense, sparse = as_float32_array(torch.cat([features, beside], 1)), np.zeros((len(features), 0), np.float32)
        else:
            dense, sparse = as_float32_array(features), as_float32_array(beside)
        offsets, ids = bin_tiles(means2d, radii, depths, width, height)
        image, final_t, n_contrib, sel_image = cpu_kernels.blend_forward(
            *arrays, dense, sparse, offsets, ids, *selection, width, height, TILE_SIZE
        )
        ctx.arrays, ctx.tiles, ctx.selection, ctx.order = (*arrays, dense, sparse), (offsets, ids), selection, order
        ctx.size, ctx.state, ctx.channels, ctx.dtype = (width, height), (final_t, n_contrib), c, features.dtype
        alpha = torch.from_numpy((1.0 - final_t).astype(np.float32)).to(features.dtype)
        image = torch.from_numpy(image).to(features.dtype)
        if order is None:
            return image[..., :c], alpha, image[..., c:]
        at_pixels = torch.empty(len(order), e, dtype=features.dtype)
        at_pixels[torch.from_numpy(order)] = torch.from_numpy(sel_image).to(features.dtype)
        return image, alpha, at_pixels

    @staticmethod
    def backward(ctx, grad_image, grad_alpha, grad_beside):
        c, order = ctx.channels, ctx.order
        if order is None:
            grad_dense, grad_sparse = torch.cat([grad_image, grad_beside], -1), np.zeros((0, 0), np.float32)
        else:
            grad_dense, grad_sparse = grad_image, as_float32_array(grad_beside[torch.from_numpy(order)])
        g_means, g_conics, g_opac, g_dense, g_sparse = cpu_kernels.blend_backward(
            *ctx.arrays,
            *ctx.tiles,
            *ctx.selection,
            *ctx.size,
            TILE_SIZE,
            *ctx.state,
            as_float32_array(grad_dense),
            as_float32_array(grad_alpha),
            grad_sparse,
            c,
            numba.get_num_threads(),
        )
        g_feat, g_beside = (g_dense[:, :c], g_dense[:, c:]) if order is None else (g_dense, g_sparse)
        g_means, g_conics, g_opac, g_feat, g_beside = (
            torch.from_numpy(np.ascontiguousarray(g)).to(ctx.dtype)
            for g in (g_means, g_conics, g_opac, g_feat, g_beside)
        )
        return g_means, g_conics, g_opac, g_feat, g_beside, None, None, None, None, None


def blend_cpu(
    means2d: torch.Tensor,
    conics: torch.Tensor,
    opacities: torch.Tensor,
    features: torch.Tensor,
    depths: torch.Tensor,
    radii: torch.Tensor,
    width: int,
    height: int,
    beside: torch.Tensor | None = None,
    pixels: torch.Tensor | None = None,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Same contract as :func:`gsseg.render.torch_blend.blend_torch` for ``features`` (N, C),
    computed by numba, and ``beside`` (N, E) blended by the same Gaussians with gradients that
    reach ``beside`` alone, as if blended over the geometry detached.

    Returns:
        image (H, W, C), alpha (H, W), and the blend of ``beside``: (H, W, E), or (P, E) at
        the flat pixel indices ``pixels`` (P,) (y W + x) alone when they are given, which
        blends those channels there alone (E = 0 when ``beside`` is None).
    """
    if beside is None:
        beside = features.new_zeros(len(features), 0)
    return _BlendCPU.apply(means2d, conics, opacities, features, beside, depths, radii, width, height, pixels)
