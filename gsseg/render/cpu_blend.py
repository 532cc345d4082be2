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


class _BlendCPU(torch.autograd.Function):
    @staticmethod
    def forward(ctx, means2d, conics, opacities, features, depths, radii, width, height, geometry_channels):
        arrays = [as_float32_array(x) for x in (means2d, conics, opacities, features)]
        offsets, ids = bin_tiles(means2d, radii, depths, width, height)
        image, final_t, n_contrib = cpu_kernels.blend_forward(*arrays, offsets, ids, width, height, TILE_SIZE)
        ctx.arrays, ctx.tiles, ctx.size = arrays, (offsets, ids), (width, height)
        ctx.state = (final_t, n_contrib)
        ctx.dtype = features.dtype
        ctx.geometry_channels = features.shape[1] if geometry_channels is None else geometry_channels
        alpha = (1.0 - final_t).astype(np.float32)
        return torch.from_numpy(image).to(features.dtype), torch.from_numpy(alpha).to(features.dtype)

    @staticmethod
    def backward(ctx, grad_image, grad_alpha):
        grads = cpu_kernels.blend_backward(
            *ctx.arrays,
            *ctx.tiles,
            *ctx.size,
            TILE_SIZE,
            *ctx.state,
            as_float32_array(grad_image),
            as_float32_array(grad_alpha),
            ctx.geometry_channels,
            numba.get_num_threads(),
        )
        g_means, g_conics, g_opac, g_feat = (torch.from_numpy(g).to(ctx.dtype) for g in grads)
        return g_means, g_conics, g_opac, g_feat, None, None, None, None, None


def blend_cpu(
    means2d: torch.Tensor,
    conics: torch.Tensor,
    opacities: torch.Tensor,
    features: torch.Tensor,
    depths: torch.Tensor,
    radii: torch.Tensor,
    width: int,
    height: int,
    geometry_channels: int | None = None,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Same contract as :func:`gsseg.render.torch_blend.blend_torch`, computed by numba; where
    ``geometry_channels`` is given, only the first that many channels of ``features`` (N, C)
    pass gradients to ``means2d``, ``conics`` and ``opacities`` (the others reach their own
    features alone, as if blended in a second pass over the geometry detached)."""
    return _BlendCPU.apply(means2d, conics, opacities, features, depths, radii, width, height, geometry_channels)
