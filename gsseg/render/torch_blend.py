"""The ``torch`` backend: tile-wise blending in plain PyTorch, differentiated by autograd.

It is the reference for the compiled ``cpu`` backend: the same binning, order and rules,
written as dense tensor algebra per 16x16 tile, so its gradients are autograd's.
"""

from __future__ import annotations

import torch

from gsseg.render.blend_rules import ALPHA_MAX, ALPHA_MIN, T_MIN
from gsseg.render.projection import TILE_SIZE, tile_rects


def blend_torch(
    means2d: torch.Tensor,
    conics: torch.Tensor,
    opacities: torch.Tensor,
    features: torch.Tensor,
    depths: torch.Tensor,
    radii: torch.Tensor,
    width: int,
    height: int,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Alpha-blend N screen-space Gaussians front to back.

    Args:
        means2d: (N, 2). conics: (N, 3). opacities: (N,). features: (N, C) values to blend.
        depths: (N,) sort keys (camera z). radii: (N,) int32, 0 = culled.
        width, height: image size in pixels.

    Returns:
        image (H, W, C) = sum_i alpha_i T_i f_i and alpha (H, W) = 1 - prod_i (1 - alpha_i).
    """
    n_ch = features.shape[1]
    image = features.new_zeros(height, width, n_ch)
    alpha_img = features.new_zeros(height, width)
    rects = tile_rects(means2d, radii, width, height)
    order = torch.argsort(depths.detach(), stable=True)
    rects = rects[order]
    tiles_x, tiles_y = -(-width // TILE_SIZE), -(-height // TILE_SIZE)
    for ty in range(tiles_y):
        rows = (rects[:, 1] <= ty) & (ty < rects[:, 3])
        for tx in range(tiles_x):
            ids = order[rows & (rects[:, 0] <= tx) & (tx < rects[:, 2])]
            if len(ids) == 0:
                continue
            y0, x0 = ty * TILE_SIZE, tx * TILE_SIZE
            y1, x1 = min(y0 + TILE_SIZE, height), min(x0 + TILE_SIZE, width)
            py, px = torch.meshgrid(
                torch.arange(y0, y1, dtype=means2d.dtype) + 0.5,
                torch.arange(x0, x1, dtype=means2d.dtype) + 0.5,
                indexing="ij",
            )
            dx = means2d[ids, 0][None] - px.reshape(-1, 1)  # (P, n)
            dy = means2d[ids, 1][None] - py.reshape(-1, 1)
            a, b, c = conics[ids].unbind(-1)
            power = -0.5 * (a * dx * dx + c * dy * dy) - b * dx * dy
            alpha = torch.clamp(opacities[ids] * torch.exp(power), max=ALPHA_MAX)
            alpha = torch.where((power <= 0) & (alpha >= ALPHA_MIN), alpha, torch.zeros_like(alpha))
            # Blending stops before the Gaussian that would take T below T_MIN: a prefix.
            reached = torch.cumprod(1 - alpha.detach(), dim=1) >= T_MIN
            alpha = alpha * reached
            one_minus = 1 - alpha
            trans = torch.cat([torch.ones_like(alpha[:, :1]), torch.cumprod(one_minus, dim=1)[:, :-1]], dim=1)
            weights = alpha * trans
            image[y0:y1, x0:x1] = (weights @ features[ids]).reshape(y1 - y0, x1 - x0, n_ch)
            alpha_img[y0:y1, x0:x1] = (1 - torch.prod(one_minus, dim=1)).reshape(y1 - y0, x1 - x0)
    return image, alpha_img
