"""Label reassignment: one label per Gaussian from the contribution matrix and/or the
learned classifier.

Normalisation: each Gaussian's column of A is divided by its sum, so Â[:, i] is the share
of Gaussian i's blended weight that fell on each label (a distribution over labels, in
[0, 1]). The prior gamma_p * p(i, l_i) (p the classifier's softmax probability, also in
[0, 1]) is added on that same scale, so gamma_p = 1 lets a fully confident prior outweigh
the masks' vote for a Gaussian seen under two labels equally often, and gamma_p = 0.2 only
breaks near-ties. Gaussians no view observed (column sum 0) keep their prior label under
``prior`` and ``classifier`` and get label 0 under ``flashsplat``.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import torch

from dataset_tools.infra.errors import InputError
from gsseg.render.contributions import Contributions

METHODS = ("prior", "flashsplat", "classifier")
MODES = ("multi", "binary")


@dataclass
class Segmentation:
    """Per-Gaussian labels and per-object selections.

    Attributes:
        labels: (N,) uint8 label of every Gaussian.
        objects: (M,) uint8 object IDs (mask labels other than 0).
        selections: (M, N) bool, Gaussians selected for each object.
        model: the fingerprint of the model labelled (:attr:`gsseg.run.Run.fingerprint`),
            "" when unknown.
        smooth, fill: the 3D regularisations applied after the reassignment
            (:mod:`gsseg.segment.regularize`; 0 and False: none).
    """

    labels: np.ndarray
    objects: np.ndarray
    selections: np.ndarray
    method: str
    mode: str
    gamma_p: float
    model: str = ""
    smooth: int = 0
    fill: bool = False

    def selection(self, obj: int) -> np.ndarray:
        """(N,) bool Gaussians of object ``obj``."""
        hit = np.flatnonzero(self.objects == obj)
        if not len(hit):
            raise InputError(
                f"object {obj} is not among the segmented objects {self.objects.tolist()}; pick one of them."
            )
        return self.selections[hit[0]]

    def settings(self) -> dict:
        """How the labels were chosen (method, mode, gamma_p, smooth, fill), as edits record it."""
        return {
            "method": self.method,
            "mode": self.mode,
            "gamma_p": self.gamma_p,
            "smooth": self.smooth,
            "fill": self.fill,
        }

    def subset(self, keep: np.ndarray) -> Segmentation:
        """The labels and selections of the Gaussians where (N,) bool ``keep`` is true."""
        return replace(self, labels=self.labels[keep], selections=self.selections[:, keep])


def normalize(weights: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Columns of (K, N) ``weights`` divided by their sums, and the (N,) bool mask of observed Gaussians."""
    total = weights.sum(0)
    observed = total > 0
    return weights / torch.where(observed, total, torch.ones_like(total)), observed


def classifier_prior(obj_feat: torch.Tensor, classifier: torch.nn.Linear) -> tuple[torch.Tensor, torch.Tensor]:
    """Each Gaussian's own prediction: l_i (N,) int64 argmax of the classifier's softmax on its
    feature (N, F), and p_i (N,) its probability."""
    with torch.no_grad():
        probs = torch.softmax(classifier(obj_feat), dim=-1)
    p, label = probs.max(dim=-1)
    return label, p


def reassign(
    contributions: Contributions,
    prior_labels: torch.Tensor,
    prior_probs: torch.Tensor,
    *,
    method: str = "prior",
    mode: str = "multi",
    gamma_p: float = 0.2,
    slack: float = 0.0,
) -> Segmentation:
    """Labels of every Gaussian.

    Args:
        contributions: A (K, N) over the mask labels.
        prior_labels, prior_probs: (N,) l_i and p(i, l_i) from :func:`classifier_prior`.
        method: ``prior`` (A + gamma_p p(i, l_i) [l = l_i], the default), ``flashsplat`` (A with
            ``slack`` added to the background's share), ``classifier`` (l_i alone).
        mode: ``multi``: argmax over labels (Eq. 9 of the paper); ``binary``: one object at a
            time, object share against the rest (plus the prior on whichever side l_i is),
            so selections may overlap; ``labels`` then give each Gaussian the last object
            (in ID order) that selected it.
        gamma_p: prior weight, any real number.
        slack: FlashSplat's background bias.
    """
    if method not in METHODS:
        raise InputError(f"unknown method {method!r}; choose one of {', '.join(METHODS)}.")
    if mode not in MODES:
        raise InputError(f"unknown mode {mode!r}; choose multi or binary.")
    labels_k = contributions.labels.astype(np.int64)
    share, observed = normalize(contributions.weights)
    n = share.shape[1]
    objects = contributions.labels[contributions.labels > 0]
    obj_ids = torch.as_tensor(objects.astype(np.int64))
    # The row of each Gaussian's prior label l_i in A (-1 where no mask shows that label):
    # the prior touches one entry per Gaussian, so it is added there, not as a (K, N) matrix.
    row_of = torch.full((256,), -1, dtype=torch.int64)
    row_of[torch.as_tensor(labels_k)] = torch.arange(len(labels_k))
    prior_row = row_of[prior_labels.clamp(0, 255)]
    has_row = torch.nonzero(prior_row >= 0).squeeze(1)
    bonus = gamma_p * prior_probs

    if method == "classifier":
        labels = prior_labels.clamp(0, 255)
        selections = labels[None, :] == obj_ids[:, None]
    elif mode == "multi":
        score = share
        if method == "prior":
            score[prior_row[has_row], has_row] += bonus[has_row]
        elif len(labels_k) and labels_k[0] == 0:
            score[0] += slack
        best = torch.as_tensor(labels_k)[score.argmax(dim=0)] if len(labels_k) else torch.zeros(n, dtype=torch.int64)
        fallback = prior_labels if method == "prior" else torch.zeros_like(prior_labels)
        labels = torch.where(observed, best, fallback)
        selections = labels[None, :] == obj_ids[:, None]
    else:
        first = int(labels_k[0] == 0) if len(labels_k) else 0  # object rows start after label 0
        fg = share[first:]
        rest = torch.sub(1.0, fg)
        rest += (bonus if method == "prior" else torch.full_like(bonus, slack))[None, :]
        selections = fg > rest
        mine = torch.zeros_like(selections)
        if method == "prior":
            # the l_i row: the prior sides with the object instead of the rest
            on_obj = has_row[prior_row[has_row] >= first]
            r = prior_row[on_obj] - first
            selections[r, on_obj] = fg[r, on_obj] + bonus[on_obj] > 1.0 - fg[r, on_obj]
            mine[r, on_obj] = True
        selections = torch.where(observed[None, :], selections, mine)
        # the last selecting object in ID order: the largest 1-based row number that selects
        # (uint8 holds it: there are at most 255 objects); 0 where none does
        if len(obj_ids):
            rank = torch.arange(1, len(obj_ids) + 1, dtype=torch.uint8)[:, None]
            last = (selections.to(torch.uint8) * rank).amax(dim=0).long()
            labels = torch.where(last > 0, obj_ids[(last - 1).clamp_min(0)], 0)
        else:
            labels = torch.zeros(n, dtype=torch.int64)
    return Segmentation(
        labels=labels.numpy().astype(np.uint8),
        objects=objects,
        selections=selections.numpy(),
        method=method,
        mode=mode,
        gamma_p=gamma_p,
    )
