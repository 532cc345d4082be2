"""What a selection leaves behind: the Gaussians that only ever drew the selected object.

The labels, and the clicks, decide each Gaussian from where its weight falls in the masks;
some that only ever drew the object carry another label all the same (a floater in front of
it, its rim that the vote gave to what lies behind). Removed without them the object leaves a
ghost: a dark face over the bush where a statue's head was. Measured in the training views:
each view's silhouette of the selection is where the selected Gaussians hold most of the
blended weight (:func:`gsseg.render.pixel_labels.segment_pixels`); a Gaussian outside the
selection whose weight, summed over the views, falls inside those silhouettes for at least
:data:`SERVED_SHARE` of it served the object alone, and goes with it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch

from gsseg.model.gaussians import Gaussians
from gsseg.render import Backend, get_backend
from gsseg.render.contributions import Masked, MaskedView, contribution_matrix
from gsseg.render.pixel_labels import segment_pixels

SERVED_SHARE = 0.9  # a Gaussian with this share of its weight inside the silhouettes served the object alone


@dataclass(frozen=True)
class Completed:
    """A selection with what served it alone: ``mask`` (N,) bool, ``added`` how many Gaussians
    joined, and the ghost share before and after: the share of the blended weight inside the
    selection's silhouettes (over the views) that Gaussians outside the selection carry."""

    mask: np.ndarray
    added: int
    ghost_before: float
    ghost_after: float


def complete_selection(
    gaussians: Gaussians, selected: np.ndarray, views: Sequence[Masked], *, backend: str | Backend = "cpu"
) -> Completed:
    """``selected`` (N,) bool and the Gaussians that served it alone in ``views`` (posed views;
    their masks are not read)."""
    backend = get_backend(backend)
    g = gaussians.detach().to(backend.device)
    silhouettes = []
    for view in views:
        pose = torch.as_tensor(view.cam_from_world, dtype=torch.float32, device=backend.device)
        shown = segment_pixels(g, selected.astype(np.uint8), view.camera, pose, backend=backend) == 1
        silhouettes.append(MaskedView(view.camera, view.cam_from_world, shown.astype(np.uint8)))
    weights = contribution_matrix(g, silhouettes, backend=backend, progress=False)
    total = weights.weights.sum(0).numpy().astype(np.float64)
    inside = np.zeros(len(selected))
    if 1 in weights.labels:
        inside = weights.weights[int(np.flatnonzero(weights.labels == 1)[0])].numpy().astype(np.float64)
    served = ~selected & (total > 0) & (inside >= SERVED_SHARE * total)
    mask = selected | served

    def ghost(kept: np.ndarray) -> float:
        return float(inside[~kept].sum() / max(inside.sum(), 1e-12))

    return Completed(mask, int(served.sum()), ghost(selected), ghost(mask))
