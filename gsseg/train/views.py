"""Training views held in memory as tensors."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from tqdm import tqdm

from dataset_tools.cameras import PinholeCamera
from dataset_tools.scene import View


@dataclass
class TrainView:
    """One view ready for training.

    Attributes:
        image: (H, W, 3) float32 in [0, 1].
        mask: (H, W) int64 object IDs, or None for a view trained on colour only.
        cam_from_world: (3, 4) float32.
    """

    name: str
    camera: PinholeCamera
    cam_from_world: torch.Tensor
    image: torch.Tensor
    mask: torch.Tensor | None


def load_views(views: list[View], *, progress: bool = True, device: str = "cpu") -> list[TrainView]:
    """Read the images and masks of ``views`` (masks must match their image's size)."""
    out = []
    for v in tqdm(views, desc="loading views", unit="view", disable=not progress, leave=False):
        mask = v.load_mask()
        out.append(TrainView(
            name=v.name,
            camera=v.camera,
            cam_from_world=torch.as_tensor(v.cam_from_world, dtype=torch.float32, device=device),
            image=torch.from_numpy(v.load_image().astype(np.float32) / 255.0).to(device),
            mask=None if mask is None else torch.from_numpy(mask.astype(np.int64)).to(device),
        ))
    return out


def camera_extent(views: list[View]) -> float:
    """3D-GS's scene scale: 1.1 x the largest distance of a camera centre from their mean."""
    centers = np.stack([v.center for v in views])
    return 1.1 * float(np.linalg.norm(centers - centers.mean(0), axis=1).max()) or 1.0
