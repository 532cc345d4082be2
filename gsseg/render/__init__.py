"""One rasterize entry point with interchangeable backends.

``cpu``    numba kernels (default without a GPU),
``torch``  plain PyTorch, the reference the others are tested against,
``gsplat`` gsplat on CUDA (chosen automatically when it is installed and a GPU is present).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from dataset_tools.cameras import PinholeCamera
from dataset_tools.errors import InputError
from gsseg.gaussians import Gaussians
from gsseg.render.cpu_blend import blend_cpu
from gsseg.render.gsplat_blend import gsplat_available, rasterize_gsplat
from gsseg.render.projection import project_gaussians
from gsseg.render.torch_blend import blend_torch
from gsseg.sh import eval_sh

BACKENDS = ("cpu", "torch", "gsplat")
_BLENDERS = {"cpu": blend_cpu, "torch": blend_torch}


@dataclass
class RenderOutput:
    """What one view renders to.

    Attributes:
        rgb: (H, W, 3) colour, composited over the background.
        features: (H, W, F) blended object features (F = 0 when not asked for).
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


def resolve_backend(name: str = "auto") -> str:
    """``auto`` -> ``gsplat`` where it can run, else ``cpu``; other names are checked."""
    if name == "auto":
        return "gsplat" if gsplat_available() else "cpu"
    if name not in BACKENDS:
        raise InputError(f"unknown backend {name!r}; choose one of auto, {', '.join(BACKENDS)}.")
    if name == "gsplat" and not gsplat_available():
        raise InputError("the gsplat backend needs a CUDA GPU and `pip install gsplat`; use --backend cpu.")
    return name


def backend_device(backend: str) -> str:
    """The torch device a resolved backend renders on."""
    return "cuda" if backend == "gsplat" else "cpu"


def to_uint8(rgb: torch.Tensor) -> np.ndarray:
    """(H, W, 3) colour in [0, 1] -> (H, W, 3) uint8 array, rounded."""
    return (rgb.detach().clamp(0, 1) * 255 + 0.5).to(torch.uint8).cpu().numpy()


def render(
    gaussians: Gaussians,
    camera: PinholeCamera,
    cam_from_world: torch.Tensor,
    *,
    sh_degree: int = 3,
    background: torch.Tensor | None = None,
    with_features: bool = True,
    backend: str = "cpu",
) -> RenderOutput:
    """Render colour, object features, alpha and depth of ``gaussians`` in one camera.

    Args:
        gaussians: the model (any dtype; float32 in training, float64 in gradient tests).
        camera: pinhole intrinsics and image size.
        cam_from_world: (3, 4) or (4, 4) world-to-camera transform.
        sh_degree: SH bands used for colour, 0..3.
        background: what lies behind the Gaussians, a (3,) colour or an (H, W, 3) image (e.g.
            a learned :class:`gsseg.environment.Environment`); black when None.
        with_features: also blend the 16-d object features.
        backend: ``cpu``, ``torch`` or ``gsplat`` (see :func:`resolve_backend`).

    Returns:
        A :class:`RenderOutput`, differentiable in every Gaussian parameter.
    """
    g = gaussians
    cam_from_world = torch.as_tensor(cam_from_world)
    R, t = cam_from_world[:3, :3].to(g.means), cam_from_world[:3, 3].to(g.means)
    dirs = torch.nn.functional.normalize(g.means + (R.T @ t), dim=-1)  # centre - camera centre
    colors = eval_sh(sh_degree, g.sh, dirs)
    values = torch.cat([colors, g.obj_feat], dim=1) if with_features else colors

    if backend == "gsplat":
        image, alpha, means2d, radii = rasterize_gsplat(
            g.means, g.quats, g.scales, g.opacities, values, cam_from_world, camera)
    elif backend in _BLENDERS:
        proj = project_gaussians(g.means, g.quats, g.scales, cam_from_world, camera, g.opacities)
        means2d, radii = proj.means2d, proj.radii
        if means2d.requires_grad:
            means2d.retain_grad()
        image, alpha = _BLENDERS[backend](
            means2d, proj.conics, g.opacities, torch.cat([values, proj.depths[:, None]], dim=1),
            proj.depths, radii, camera.width, camera.height)
    else:
        raise InputError(f"unknown backend {backend!r}; choose one of {', '.join(BACKENDS)}.")

    rgb = image[..., :3]
    if background is not None:
        rgb = rgb + (1 - alpha[..., None]) * background.to(rgb)
    return RenderOutput(rgb=rgb, features=image[..., 3:-1], alpha=alpha, depth=image[..., -1],
                        means2d=means2d, radii=radii)
