"""The contribution matrix of FlashSplat: how much each Gaussian shows each mask label.

    A[k, i] = sum over views v and pixels p with M_v(p) = labels[k] of alpha_i(p) T_i(p)

computed with the blending rules of training, one pass per view on the chosen backend
(:meth:`gsseg.render.backends.Backend.contributions`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np
import torch
from tqdm import tqdm

from dataset_tools.cameras import PinholeCamera
from gsseg.gaussians import Gaussians
from gsseg.render.backends import Backend, get_backend


class Masked(Protocol):
    """A posed view whose object-ID map can be read: a scene's View, or a MaskedView."""

    camera: PinholeCamera
    cam_from_world: np.ndarray

    def load_mask(self) -> np.ndarray | None: ...


@dataclass
class MaskedView:
    """A view with its object-ID map in memory: camera, (3, 4) cam_from_world, (H, W) uint8 mask."""

    camera: PinholeCamera
    cam_from_world: np.ndarray
    mask: np.ndarray

    def load_mask(self) -> np.ndarray:
        return self.mask


@dataclass
class Contributions:
    """labels: (K,) uint8, the mask labels seen in any view, sorted. weights: (K, N) float32.
    model: the fingerprint of the model they were computed for, "" when unknown. masks: the
    mask folder that voted, "" when unknown."""

    labels: np.ndarray
    weights: torch.Tensor
    model: str = ""
    masks: str = ""


def contribution_matrix(
    gaussians: Gaussians, views: Sequence[Masked], *, backend: str | Backend = "cpu", progress: bool = True
) -> Contributions:
    """Sum alpha * T per Gaussian and mask label over ``views``.

    ``cpu`` accumulates in a numba forward pass; ``torch`` and ``gsplat`` obtain the same sums
    as a gradient, on the backend's device. Memory: (K, N) float32 plus one such buffer per
    CPU thread, and one mask at a time (masks are read twice: once for the label set, once
    to accumulate).
    """
    backend = get_backend(backend)
    labels = np.unique(np.concatenate([np.unique(v.load_mask()) for v in views])) if views else np.zeros(0, np.uint8)
    rows = np.full(256, -1, np.int64)
    rows[labels] = np.arange(len(labels))
    g = gaussians.detach().to(backend.device)
    total = torch.zeros(len(labels), len(g))
    for view in tqdm(views, desc="contributions", unit="view", disable=not progress, leave=False):
        pose = torch.as_tensor(view.cam_from_world, dtype=torch.float32, device=backend.device)
        total += backend.contributions(
            g.means, g.quats, g.scales, g.opacities, pose, view.camera, rows[view.load_mask()], len(labels)
        )
    return Contributions(labels=labels.astype(np.uint8), weights=total)
