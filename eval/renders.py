"""What the metrics and the report need from a run, rendered once per test view."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from dataset_tools.scene import View
from gsseg.environment import Environment, background_image
from gsseg.gaussians import Gaussians
from gsseg.render import backend_device, render, to_uint8
from gsseg.render_views import segment_pixels
from gsseg.segment.reassign import Segmentation

MIN_ALPHA = 0.5


@dataclass
class ViewRenders:
    """One test view: the photo and ground truth, and what the run makes of it.

    image (H, W, 3) uint8; truth (H, W) uint8 ground-truth IDs or None; rgb (H, W, 3) uint8
    render; visible (H, W) uint8 predicted labels, each pixel the label with the largest
    blended weight (0 where alpha < 0.5); extracted {label: (H, W) bool}, each predicted
    object's Gaussians rendered alone, alpha >= 0.5.
    """

    stem: str
    image: np.ndarray
    truth: np.ndarray | None
    rgb: np.ndarray
    visible: np.ndarray
    extracted: dict[int, np.ndarray]


@torch.no_grad()
def render_view(gaussians: Gaussians, segmentation: Segmentation, view: View, *, sh_degree: int, backend: str,
                truth: np.ndarray | None, environment: Environment | None = None) -> ViewRenders:
    """The renders of one view (``gaussians`` on ``backend``'s device, the colour over ``environment``)."""
    pose = torch.as_tensor(view.cam_from_world, dtype=torch.float32, device=backend_device(backend))
    rgb = to_uint8(render(gaussians, view.camera, pose, sh_degree=sh_degree,
                          background=background_image(environment, view.camera, pose),
                          with_features=False, backend=backend).rgb)
    visible = segment_pixels(gaussians, segmentation.labels, view.camera, pose, backend=backend, min_alpha=MIN_ALPHA)
    extracted = {}
    for label in segmentation.objects:
        alone = gaussians.select(torch.as_tensor(segmentation.selection(int(label)), device=gaussians.means.device))
        alpha = render(alone, view.camera, pose, sh_degree=0, with_features=False, backend=backend).alpha
        extracted[int(label)] = alpha.cpu().numpy() >= MIN_ALPHA
    return ViewRenders(view.stem, view.load_image(), truth, rgb, visible, extracted)
