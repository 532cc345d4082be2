"""The contribution matrix of FlashSplat: how much each Gaussian shows each mask label.

    A[k, i] = sum over views v and pixels p with M_v(p) = labels[k] of alpha_i(p) T_i(p)

computed with the blending rules of training, in one no-grad pass per view.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
import torch
from tqdm import tqdm

from dataset_tools.cameras import PinholeCamera
from gsseg.gaussians import Gaussians
from gsseg.render import backend_device, cpu_kernels, render
from gsseg.render.cpu_blend import as_float32_array, bin_tiles
from gsseg.render.projection import TILE_SIZE, project_gaussians


@dataclass
class MaskedView:
    """A view with its object-ID map: camera, (3, 4) cam_from_world, (H, W) uint8 mask."""

    camera: PinholeCamera
    cam_from_world: np.ndarray
    mask: np.ndarray


@dataclass
class Contributions:
    """labels: (K,) uint8, the mask labels seen in any view, sorted. weights: (K, N) float32."""

    labels: np.ndarray
    weights: torch.Tensor


@torch.no_grad()
def _weights_cpu(g: Gaussians, view: MaskedView, rows: np.ndarray, n_rows: int) -> torch.Tensor:
    pose = torch.as_tensor(view.cam_from_world, dtype=torch.float32)
    opacities = g.opacities
    proj = project_gaussians(g.means, g.quats, g.scales, pose, view.camera, opacities)
    width, height = view.camera.width, view.camera.height
    offsets, ids = bin_tiles(proj.means2d, proj.radii, proj.depths, width, height)
    arrays = [as_float32_array(x) for x in (proj.means2d, proj.conics, opacities)]
    out = cpu_kernels.accumulate_weights(*arrays, offsets, ids, width, height, TILE_SIZE,
                                         rows[view.mask].astype(np.int32), n_rows, numba.get_num_threads())
    return torch.from_numpy(out)


def _weights_autograd(g: Gaussians, view: MaskedView, rows: np.ndarray, n_rows: int, backend: str) -> torch.Tensor:
    """Through any differentiable backend: the gradient of sum_p <rendered values, one_hot(M(p))>
    with respect to per-Gaussian values is exactly alpha_i T_i summed per label."""
    device = g.means.device
    probe = torch.zeros(len(g), n_rows, device=device, requires_grad=True)
    carrier = Gaussians(**{**g.tensors(), "obj_feat": probe})
    out = render(carrier, view.camera, torch.as_tensor(view.cam_from_world, dtype=torch.float32, device=device),
                 sh_degree=0, backend=backend)
    row = torch.as_tensor(rows[view.mask], device=device, dtype=torch.int64)[..., None]  # (H, W, 1)
    (out.features.gather(-1, row.clamp_min(0)) * (row >= 0)).sum().backward()
    return probe.grad.T.cpu()


def contribution_matrix(gaussians: Gaussians, views: list[MaskedView], *, backend: str = "cpu",
                        progress: bool = True) -> Contributions:
    """Sum alpha * T per Gaussian and mask label over ``views``.

    ``cpu`` accumulates in a numba forward pass; ``torch`` and ``gsplat`` obtain the same sums
    as a gradient, on the backend's device. Memory: (K, N) float32 plus one such buffer per
    CPU thread.
    """
    labels = np.unique(np.concatenate([np.unique(v.mask) for v in views])) if views else np.zeros(0, np.uint8)
    rows = np.full(256, -1, np.int64)
    rows[labels] = np.arange(len(labels))
    g = gaussians.detach().to(backend_device(backend))
    total = torch.zeros(len(labels), len(g))
    for view in tqdm(views, desc="contributions", unit="view", disable=not progress, leave=False):
        if backend == "cpu":
            total += _weights_cpu(g, view, rows, len(labels))
        else:
            total += _weights_autograd(g, view, rows, len(labels), backend)
    return Contributions(labels=labels.astype(np.uint8), weights=total)
