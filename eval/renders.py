"""What the metrics and the report need from a run, rendered once per test view."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from dataset_tools.scene import View
from gsseg.render import Backend, get_backend
from gsseg.render.pixel_labels import segment_pixels
from gsseg.run.loaded import Run
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
def render_view(
    run: Run, segmentation: Segmentation, view: View, *, backend: str | Backend, truth: np.ndarray | None
) -> ViewRenders:
    """The renders of one view by a segmented run."""
    backend = get_backend(backend)
    gaussians = run.gaussians_on(backend.device)
    pose = torch.as_tensor(view.cam_from_world, dtype=torch.float32, device=backend.device)
    visible = segment_pixels(gaussians, segmentation.labels, view.camera, pose, backend=backend, min_alpha=MIN_ALPHA)
    extracted = {}
    for label in segmentation.objects:
        alone = gaussians.select(torch.as_tensor(segmentation.selection(int(label)), device=backend.device))
        alpha = run.render(view, gaussians=alone, background="black", sh_degree=0, backend=backend).alpha
        extracted[int(label)] = alpha.cpu().numpy() >= MIN_ALPHA
    return ViewRenders(view.stem, view.load_image(), truth, run.render_rgb(view, backend=backend), visible, extracted)
