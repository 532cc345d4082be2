"""Rendering: one entry point, :func:`render`, over interchangeable backends.

``render`` evaluates the Gaussians' SH colours for the camera, has a backend
(:mod:`gsseg.render.backends`) project and blend them with their object features, and
composites the result over a background. The contribution pass of FlashSplat lives beside
it (:mod:`gsseg.render.contributions`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from dataset_tools.cameras import PinholeCamera
from gsseg.model.gaussians import Gaussians
from gsseg.model.sh import MAX_DEGREE, eval_sh
from gsseg.model.sh_cpu import eval_sh_cpu
from gsseg.render.backends import BACKENDS, Backend, get_backend

__all__ = ["BACKENDS", "Backend", "RenderOutput", "get_backend", "render", "surface_depth", "to_uint8"]


@dataclass
class RenderOutput:
    """What one view renders to.

    Attributes:
        rgb: (H, W, 3) colour, composited over the background.
        features: (H, W, F) blended object features (F = 0 when not asked for), or (P, F) at
            the pixels asked for.
        alpha: (H, W) accumulated opacity.
        depth: (H, W) alpha-weighted camera depth, sum_i alpha_i T_i z_i.
        means2d: screen centres, (N, 2) or (1, N, 2); after ``backward`` its ``.grad`` is the
            view-space positional gradient that densification uses.
        radii: (N,) int32 footprint radii in pixels, 0 where a Gaussian is not seen.
    """

    rgb: torch.Tensor
    features: torch.Tensor
    alpha: torch.Tensor
    depth: torch.Tensor
    means2d: torch.Tensor
    radii: torch.Tensor


def to_uint8(rgb: torch.Tensor) -> np.ndarray:
    """(H, W, 3) colour in [0, 1] -> (H, W, 3) uint8 array, rounded."""
    return (rgb.detach().clamp(0, 1) * 255 + 0.5).to(torch.uint8).cpu().numpy()


def surface_depth(out: RenderOutput, min_alpha: float = 0.5) -> np.ndarray:
    """(H, W) float32 camera depth of the surface each pixel sees: the blended depth over the
    blended opacity where that opacity is at least ``min_alpha``, 0 elsewhere."""
    alpha = out.alpha.detach().cpu().numpy()
    depth = out.depth.detach().cpu().numpy() / np.maximum(alpha, 1e-6)
    return np.where(alpha >= min_alpha, depth, 0.0).astype(np.float32)


def render(
    gaussians: Gaussians,
    camera: PinholeCamera,
    cam_from_world: torch.Tensor,
    *,
    sh_degree: int = MAX_DEGREE,
    background: torch.Tensor | None = None,
    with_features: bool = True,
    feature_geometry_grad: bool = True,
    feature_pixels: torch.Tensor | None = None,
    backend: str | Backend = "cpu",
) -> RenderOutput:
    """Render colour, object features, alpha and depth of ``gaussians`` in one camera.

    Args:
        gaussians: the model (any dtype; float32 in training, float64 in gradient tests), on
            the backend's device.
        camera: pinhole intrinsics and image size.
        cam_from_world: (3, 4) or (4, 4) world-to-camera transform.
        sh_degree: SH bands used for colour, 0..3.
        background: what lies behind the Gaussians, a (3,) colour or an (H, W, 3) image (e.g.
            a learned :class:`gsseg.model.environment.Environment`); black when None.
        with_features: also blend the 16-d object features.
        feature_geometry_grad: let gradients of the features reach the geometry (means,
            rotations, scales, opacities, and ``means2d``, hence densification); when False
            the features are blended as over the geometry detached
            (:meth:`Backend.rasterize_beside`), and their gradients reach only ``obj_feat``.
        feature_pixels: (P,) flat pixel indices (y W + x): the features at these pixels alone,
            (P, F), which the ``cpu`` backend blends there alone when ``feature_geometry_grad``
            is False (a loss on sampled pixels then pays for those pixels' features only).
        backend: a :class:`Backend` or its name (see :func:`get_backend`).

    Returns:
        A :class:`RenderOutput`, differentiable in every Gaussian parameter.
    """
    g = gaussians
    cam_from_world = torch.as_tensor(cam_from_world)
    if tuple(cam_from_world.shape) not in ((3, 4), (4, 4)):
        raise ValueError(f"render: cam_from_world has shape {tuple(cam_from_world.shape)}, expected (3, 4) or (4, 4)")
    if background is not None and background.shape[-1] != 3:
        raise ValueError(f"render: background has shape {tuple(background.shape)}, expected (3,) or (H, W, 3)")
    R, t = cam_from_world[:3, :3].to(g.means), cam_from_world[:3, 3].to(g.means)
    dirs = torch.nn.functional.normalize(g.means + (R.T @ t), dim=-1)  # centre - camera centre
    on_cpu = g.means.device.type == "cpu" and g.means.dtype == torch.float32
    colors = (eval_sh_cpu if on_cpu else eval_sh)(sh_degree, g.sh, dirs)  # the same colours
    backend = get_backend(backend)
    if with_features and not feature_geometry_grad:
        raster, features = backend.rasterize_beside(
            g.means, g.quats, g.scales, g.opacities, colors, g.obj_feat, cam_from_world, camera, feature_pixels
        )
    else:
        values = torch.cat([colors, g.obj_feat], dim=1) if with_features else colors
        raster = backend.rasterize(g.means, g.quats, g.scales, g.opacities, values, cam_from_world, camera)
        features = raster.image[..., 3:]
        if feature_pixels is not None:
            features = features.reshape(-1, features.shape[-1])[feature_pixels]
    rgb = raster.image[..., :3]
    if background is not None:
        rgb = rgb + (1 - raster.alpha[..., None]) * background.to(rgb)
    return RenderOutput(
        rgb=rgb, features=features, alpha=raster.alpha, depth=raster.depth, means2d=raster.means2d, radii=raster.radii
    )
