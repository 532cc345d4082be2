"""What a selection leaves behind: the Gaussians that only ever drew the selected object.

The labels, and the clicks, decide each Gaussian from where its weight falls in the masks;
some that only ever drew the object carry another label all the same (a floater in front of
it, its rim that the vote gave to what lies behind). Removed without them the object leaves a
ghost: a dark face over the bush where a statue's head was. Measured in the training views:
each view's silhouette of the selection is where the selected Gaussians hold most of the
blended weight (:func:`gsseg.render.pixel_labels.render_labels`); a Gaussian outside the
selection whose weight, summed over the views, falls inside those silhouettes for at least
:data:`SERVED_SHARE` of it served the object alone, and goes with it. So does one inside
the object: within its reach (the convex hull of the selection's centres pushed out by
:data:`EXTENT` times their median largest scale, as far as its Gaussians draw), and hidden
by it from every view, as space carving reads a visual hull (its centre inside the
silhouette and behind the surface the selection shows there in every view whose image it
falls in, two at least). No photo saw it; removed with the object it would show what
training left inside it, as a dark speck at a can's foot. Within that reach a Gaussian also
goes when most of its weight, :data:`HULL_SHARE`, falls inside the silhouettes: the
object's own rim and foot that the vote gave to the floor, which win a few pixels of their
own and so never reach :data:`SERVED_SHARE`; at an object's foot they lie below its lowest
centres, beyond their hull. What the object hides beyond its reach (the wall behind it)
stays for the fill of :mod:`gsseg.fill` to cover, and what shows through a gap within its
reach stays, its weight falling outside the silhouettes.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch
from scipy.spatial import ConvexHull, QhullError

from dataset_tools.cameras import PinholeCamera
from gsseg.model.gaussians import Gaussians
from gsseg.render import Backend, get_backend, surface_depth
from gsseg.render.contributions import Masked, MaskedView, contribution_matrix
from gsseg.render.pixel_labels import render_labels

SERVED_SHARE = 0.9  # a Gaussian with this share of its weight inside the silhouettes served the object alone
HULL_SHARE = 0.5  # within the selection's reach, this share of it is enough
EXTENT = 3.0  # the selection reaches this many of its Gaussians' median largest scale beyond its centres' hull
BEHIND = 0.02  # a centre less than this share of its depth in front of the selection's surface lies behind it


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
    their masks are not read), or that lie within its reach and that it hides from every one
    of them or whose weight falls mostly inside its silhouettes."""
    backend = get_backend(backend)
    g = gaussians.detach().to(backend.device)
    means = g.means.cpu().numpy().astype(np.float64)
    silhouettes, in_image, behind = [], np.zeros(len(selected), int), np.zeros(len(selected), int)
    for view in views:
        pose = torch.as_tensor(view.cam_from_world, dtype=torch.float32, device=backend.device)
        labels, out = render_labels(g, selected.astype(np.uint8), view.camera, pose, backend=backend)
        shown = labels == 1
        silhouettes.append(MaskedView(view.camera, view.cam_from_world, shown.astype(np.uint8)))
        rows, hidden = _behind(
            means, view.camera, np.asarray(view.cam_from_world, np.float64), shown, surface_depth(out)
        )
        in_image[rows] += 1
        behind[rows[hidden]] += 1
    weights = contribution_matrix(g, silhouettes, backend=backend, progress=False)
    total = weights.weights.sum(0).numpy().astype(np.float64)
    inside = np.zeros(len(selected))
    if 1 in weights.labels:
        inside = weights.weights[int(np.flatnonzero(weights.labels == 1)[0])].numpy().astype(np.float64)
    drawn = total > 0
    hidden = (in_image >= 2) & (behind == in_image)
    within = ~selected & (hidden | (drawn & (inside >= HULL_SHARE * total)))
    reach = EXTENT * float(np.median(g.scales.amax(1).cpu().numpy()[selected])) if selected.any() else 0.0
    within[within] = _enclosed(means[within], means[selected], reach)
    served = ~selected & ((drawn & (inside >= SERVED_SHARE * total)) | within)
    mask = selected | served

    def ghost(kept: np.ndarray) -> float:
        return float(inside[~kept].sum() / max(inside.sum(), 1e-12))

    return Completed(mask, int(served.sum()), ghost(selected), ghost(mask))


def _behind(
    means: np.ndarray, camera: PinholeCamera, cam_from_world: np.ndarray, silhouette: np.ndarray, depth: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The rows of ``means`` (N, 3) whose centres fall in the view's image (K,), and whether
    each lies inside the selection's ``silhouette`` (H, W) bool and behind the surface it
    shows there (``depth`` (H, W), less than :data:`BEHIND` of it in front) (K,) bool."""
    pc = means @ cam_from_world[:3, :3].T + cam_from_world[:3, 3]
    rows, u, v = camera.pixels(pc, camera.near)
    return rows, silhouette[v, u] & (pc[rows, 2] >= (1 - BEHIND) * depth[v, u])


def _enclosed(points: np.ndarray, hull: np.ndarray, margin: float) -> np.ndarray:
    """(P,) bool: which ``points`` (P, 3) lie inside the convex hull of ``hull`` (M, 3) pushed
    out by ``margin`` along each face's normal (none where it spans no volume)."""
    if len(points) == 0 or len(hull) < 4:
        return np.zeros(len(points), bool)
    try:
        faces = ConvexHull(hull).equations  # (F, 4): unit outward normal, offset; <= 0 inside
    except QhullError:
        return np.zeros(len(points), bool)
    return (points @ faces[:, :3].T + faces[:, 3]).max(1) <= margin
