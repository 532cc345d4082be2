"""The contribution matrix of FlashSplat: how much each Gaussian shows each mask label.

    A[k, i] = sum over views v and pixels p with M_v(p) = labels[k] of alpha_i(p) T_i(p)

computed with the blending rules of training, one pass per view on the chosen backend
(:meth:`gsseg.render.backends.Backend.contributions`). The same pass can keep the terms of each
view apart: :class:`RegionWeights`, each Gaussian's weight in every mask region of every view,
from which a click's object is found (:mod:`gsseg.segment.clicks`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np
import scipy.sparse as sp
import torch
from tqdm import tqdm

from dataset_tools.cameras import PinholeCamera
from gsseg.model.gaussians import Gaussians
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


# A Gaussian's weight in a region under this (a thousandth of a pixel) is left out of RegionWeights.
REGION_WEIGHT_FLOOR = 1e-3
# A label holding SCENE_SHARE of the blended weight of SCENE_VIEWS of the views covers most
# of every view: it is the scene, not an object in it.
SCENE_SHARE = 0.5
SCENE_VIEWS = 0.75


@dataclass
class RegionWeights:
    """Each Gaussian's blended weight alpha_i T_i summed over the pixels of each mask region
    (a label in one view) of one or more mask folders (layers).

    Attributes:
        matrix: (R, N) float32 CSR matrix, a row per region; weights under
            :data:`REGION_WEIGHT_FLOOR` are left out.
        view: (R,) int32 index of the region's view. label: (R,) uint8 its mask label.
        layer: (R,) uint8 index into ``layers``, the mask folders.
        model: the fingerprint of the model they were computed for, "" when unknown.
    """

    matrix: sp.csr_matrix
    view: np.ndarray
    label: np.ndarray
    layer: np.ndarray
    layers: tuple[str, ...]
    model: str = ""

    def covering(self, share: float = SCENE_SHARE, views: float = SCENE_VIEWS) -> set[int]:
        """The labels of the first layer whose regions hold at least ``share`` of the blended
        weight of their view in at least ``views`` of its views: labels that cover most of
        every view, the scene rather than an object in it."""
        first, weight, totals, seen = self._first_layer()
        wide = self.label[first][weight >= share * totals[self.view[first]]]
        counts = np.bincount(wide, minlength=256)
        return {int(k) for k in np.flatnonzero(counts >= views * max(len(seen), 1))}

    def view_weights(self) -> sp.csr_matrix:
        """(V, N) each Gaussian's blended weight in each view of the first layer, over all the
        view's regions (V: one more than the highest view index)."""
        first = np.flatnonzero(self.layer == 0)
        n_views = int(self.view.max()) + 1 if len(self.view) else 0
        gather = sp.csr_matrix(
            (np.ones(len(first), np.float32), (self.view[first], np.arange(len(first)))), shape=(n_views, len(first))
        )
        return (gather @ self.matrix[first]).tocsr()

    def _first_layer(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The first layer's rows (R1,), each one's blended weight (R1,), each view's total
        weight over them (V,), and the views that hold one (S,)."""
        first = np.flatnonzero(self.layer == 0)
        weight = np.asarray(self.matrix[first].sum(1)).ravel()
        return first, weight, np.bincount(self.view[first], weight), np.unique(self.view[first])

    def subset(self, keep: np.ndarray) -> RegionWeights:
        """The weights of the Gaussians where (N,) bool ``keep`` is true (a model after a removal)."""
        return RegionWeights(self.matrix[:, np.flatnonzero(keep)], self.view, self.label, self.layer, self.layers, "")

    @classmethod
    def stack(cls, parts: Sequence[RegionWeights]) -> RegionWeights:
        """The layers of ``parts`` (each of one layer, of the same model) as one."""
        return cls(
            sp.vstack([p.matrix for p in parts]).tocsr(),
            np.concatenate([p.view for p in parts]),
            np.concatenate([p.label for p in parts]),
            np.concatenate([np.full(len(p.view), k, np.uint8) for k, p in enumerate(parts)]),
            tuple(name for p in parts for name in p.layers),
            parts[0].model if parts else "",
        )


@dataclass
class Contributions:
    """labels: (K,) uint8, the mask labels seen in any view, sorted. weights: (K, N) float32.
    model: the fingerprint of the model they were computed for, "" when unknown. masks: the
    mask folder that voted, "" when unknown. regions: the same weights per view, where asked for."""

    labels: np.ndarray
    weights: torch.Tensor
    model: str = ""
    masks: str = ""
    regions: RegionWeights | None = None


def contribution_matrix(
    gaussians: Gaussians,
    views: Sequence[Masked],
    *,
    backend: str | Backend = "cpu",
    regions: bool = False,
    progress: bool = True,
) -> Contributions:
    """Sum alpha * T per Gaussian and mask label over ``views``; with ``regions``, also keep
    each view's sums apart (:class:`RegionWeights`, one layer, its views numbered as given).

    ``cpu`` accumulates in a numba forward pass; ``torch`` and ``gsplat`` obtain the same sums
    as a gradient, on the backend's device. Memory: (K, N) float32 on the backend's device
    and one such buffer per CPU thread; of each view's weights only those kept in the regions
    leave the device; one mask at a time (masks are read twice: once for the label set, once
    to accumulate).
    """
    backend = get_backend(backend)
    labels = np.unique(np.concatenate([np.unique(v.load_mask()) for v in views])) if views else np.zeros(0, np.uint8)
    rows = np.full(256, -1, np.int64)
    rows[labels] = np.arange(len(labels))
    g = gaussians.detach().to(backend.device)
    total = torch.zeros(len(labels), len(g), device=backend.device)
    blocks, view_of, label_of = [], [], []
    for k, view in enumerate(tqdm(views, desc="contributions", unit="view", disable=not progress, leave=False)):
        pose = torch.as_tensor(view.cam_from_world, dtype=torch.float32, device=backend.device)
        weights = backend.contributions(
            g.means, g.quats, g.scales, g.opacities, pose, view.camera, rows[view.load_mask()], len(labels)
        )
        total += weights
        if regions:
            seen, block = _held_rows(weights)
            blocks.append(block)
            view_of.append(np.full(len(seen), k, np.int32))
            label_of.append(labels[seen].astype(np.uint8))
    kept = None
    if regions:
        kept = RegionWeights(
            sp.vstack(blocks).tocsr() if blocks else sp.csr_matrix((0, len(g)), dtype=np.float32),
            np.concatenate(view_of) if view_of else np.zeros(0, np.int32),
            np.concatenate(label_of) if label_of else np.zeros(0, np.uint8),
            np.zeros(sum(len(v) for v in view_of), np.uint8),
            ("",),
        )
    return Contributions(labels=labels.astype(np.uint8), weights=total.cpu(), regions=kept)


def _held_rows(weights: torch.Tensor) -> tuple[np.ndarray, sp.csr_matrix]:
    """The rows of (K, N) ``weights`` (on any device) that hold any weight, (S,) int64, and
    those rows as an (S, N) float32 CSR matrix without the weights under
    :data:`REGION_WEIGHT_FLOOR`. Only the kept entries leave the device."""
    seen = torch.nonzero(weights.sum(1) > 0).ravel()
    position = torch.full((len(weights),), -1, dtype=torch.int64, device=weights.device)
    position[seen] = torch.arange(len(seen), device=weights.device)
    row, col = torch.nonzero(weights >= REGION_WEIGHT_FLOOR, as_tuple=True)
    values = weights[row, col]
    matrix = sp.csr_matrix(
        (values.cpu().numpy(), (position[row].cpu().numpy(), col.cpu().numpy())), shape=(len(seen), weights.shape[1])
    )
    return seen.cpu().numpy(), matrix
