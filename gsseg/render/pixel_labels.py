"""Which label each pixel of a render shows: the classifier's argmax on the rendered
features, or the Gaussian label with the largest blended weight."""

from __future__ import annotations

import numpy as np
import torch

from dataset_tools.cameras import PinholeCamera
from gsseg.model.gaussians import Gaussians
from gsseg.render import Backend, RenderOutput, render


def classify_pixels(features: torch.Tensor, classifier: torch.nn.Linear) -> torch.Tensor:
    """(H, W) int64 argmax of the classifier on rendered object features (H, W, F)."""
    return classifier(features).argmax(dim=-1)


def segment_pixels(
    gaussians: Gaussians,
    labels: np.ndarray,
    camera: PinholeCamera,
    cam_from_world: torch.Tensor,
    *,
    backend: str | Backend,
    min_alpha: float = 0.5,
) -> np.ndarray:
    """(H, W) uint8: each pixel takes the Gaussian label with the largest blended weight
    (labels (N,) uint8), 0 where the accumulated alpha is below ``min_alpha``."""
    return render_labels(gaussians, labels, camera, cam_from_world, backend=backend, min_alpha=min_alpha)[0]


def render_labels(
    gaussians: Gaussians,
    labels: np.ndarray,
    camera: PinholeCamera,
    cam_from_world: torch.Tensor,
    *,
    backend: str | Backend,
    min_alpha: float = 0.5,
) -> tuple[np.ndarray, RenderOutput]:
    """:func:`segment_pixels`, and the render it reads them from (its alpha and depth are the
    model's; its features, one channel per label present)."""
    present = np.unique(labels)
    index = np.searchsorted(present, labels)
    one_hot = torch.nn.functional.one_hot(torch.as_tensor(index), len(present)).to(gaussians.means)
    out = render(
        Gaussians(**{**gaussians.tensors(), "obj_feat": one_hot}), camera, cam_from_world, sh_degree=0, backend=backend
    )
    best = torch.as_tensor(present)[out.features.argmax(dim=-1).cpu()]
    return np.where(out.alpha.cpu().numpy() >= min_alpha, best.numpy(), 0).astype(np.uint8), out
