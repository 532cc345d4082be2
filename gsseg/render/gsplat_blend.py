"""The ``gsplat`` backend: gsplat's CUDA rasterizer with the same projection, tiles and outputs.

One rule differs: gsplat clamps a Gaussian's alpha at a pixel to 0.999, where 3D-GS and the
``cpu`` and ``torch`` backends clamp to 0.99 (:mod:`gsseg.render.blend_rules`). Below that
clamp the backends agree to float32 rounding (``tests/test_render.py``).
"""

from __future__ import annotations

import torch

from dataset_tools.cameras import PinholeCamera
from gsseg.render.projection import EPS_2D, TILE_SIZE

GSPLAT_ALPHA_MAX = 0.999  # gsplat's clamp of one Gaussian's alpha at one pixel


def gsplat_available() -> bool:
    """True where gsplat imports and a CUDA device is present."""
    if not torch.cuda.is_available():
        return False
    try:
        import gsplat  # noqa: F401
    except ImportError:
        return False
    return True


def rasterize_gsplat(
    means: torch.Tensor,
    quats: torch.Tensor,
    scales: torch.Tensor,
    opacities: torch.Tensor,
    features: torch.Tensor,
    cam_from_world: torch.Tensor,
    camera: PinholeCamera,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """Project and blend on CUDA with gsplat.

    Args:
        means (N, 3), quats (N, 4), scales (N, 3), opacities (N,), features (N, C) on a CUDA device;
        cam_from_world (3, 4) or (4, 4); camera: pinhole intrinsics.

    Returns:
        image (H, W, C + 1) whose last channel is the blended depth, alpha (H, W),
        means2d (1, N, 2) screen centres with their gradient retained (for densification),
        radii (N,).
    """
    from gsplat import rasterization

    device = means.device
    viewmat = torch.eye(4, device=device, dtype=means.dtype)
    viewmat[:3] = cam_from_world[:3].to(device=device, dtype=means.dtype)
    K = torch.as_tensor(camera.K, dtype=means.dtype, device=device)
    image, alpha, meta = rasterization(
        means=means,
        quats=quats,
        scales=scales,
        opacities=opacities,
        colors=features,
        viewmats=viewmat[None],
        Ks=K[None],
        width=camera.width,
        height=camera.height,
        near_plane=camera.near,
        eps2d=EPS_2D,
        tile_size=TILE_SIZE,
        render_mode="RGB+D",
        packed=False,
        rasterize_mode="classic",
    )
    means2d = meta["means2d"]
    if means2d.requires_grad:
        means2d.retain_grad()
    radii = meta["radii"][0]
    if radii.dim() == 2:  # gsplat >= 1.5 gives per-axis radii
        radii = radii.max(dim=-1).values
    return image[0], alpha[0, ..., 0], means2d, radii
