"""What a selection leaves behind (gsseg.segment.served)."""

from __future__ import annotations

import numpy as np
import torch

from dataset_tools.cameras import CameraPose, PinholeCamera
from dataset_tools.synth.camera_paths import look_at
from gsseg.model.gaussians import Gaussians
from gsseg.segment.served import complete_selection


def _blobs(centres: np.ndarray, scale: float, opacity: float, colour: float) -> dict[str, torch.Tensor]:
    n = len(centres)
    return {
        "means": torch.as_tensor(centres, dtype=torch.float32),
        "log_scales": torch.full((n, 3), float(np.log(scale))),
        "quats": torch.tensor([[1.0, 0, 0, 0]]).repeat(n, 1),
        "opacity_logits": torch.full((n,), float(np.log(opacity / (1 - opacity)))),
        "sh_dc": torch.full((n, 3), colour),
        "sh_rest": torch.zeros(n, 15, 3),
        "obj_feat": torch.zeros(n, 16),
    }


def test_a_patch_that_covers_the_object_in_every_view_goes_with_it():
    """A ball of 400 opaque Gaussians (the selection), a patch of 40 on its face towards the
    cameras (unselected: they win their own pixels in every view, as the gold highlights on a
    bronze head's crown do) and a wall of 400 behind it, seen from five cameras within 25
    degrees of the patch's direction. The patch lies inside the ball's silhouette in every
    view: it served the object alone and joins the selection, and its part of the ghost
    share goes; the wall, seen around the ball, stays."""
    rng = np.random.default_rng(0)
    ball = rng.normal(size=(400, 3))
    ball = 0.5 * ball / np.linalg.norm(ball, axis=1, keepdims=True)
    cap = rng.normal(size=(40, 3)) * [0.08, 0.08, 0.0] + [0.0, 0.0, 0.55]
    wall = np.c_[rng.uniform(-2, 2, (400, 2)), np.full(400, -1.5)]
    parts = [_blobs(ball, 0.08, 0.99, 0.5), _blobs(cap, 0.05, 0.99, 1.5), _blobs(wall, 0.15, 0.99, -1.0)]
    g = Gaussians(**{k: torch.cat([p[k] for p in parts]) for k in parts[0]})
    selected = np.r_[np.ones(400, bool), np.zeros(440, bool)]
    camera = PinholeCamera(64, 64, 60.0, 60.0, 32.0, 32.0)
    views = []
    tilt = np.radians(25)
    for a in np.radians([0, 72, 144, 216, 288]):
        eye = 4.0 * np.array([np.sin(tilt) * np.cos(a), np.sin(tilt) * np.sin(a), np.cos(tilt)])
        views.append(CameraPose(camera, look_at(eye, np.zeros(3))))
    done = complete_selection(g, selected, views)
    assert done.mask[400:440].all() and not done.mask[440:].any()
    assert done.added == 40
    assert done.ghost_after < 0.25 * done.ghost_before  # what remains: the wall through the ball's soft rim
