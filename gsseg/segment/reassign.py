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
from gsseg.segment.label_options import LabelOptions


@dataclass
class Segmentation:
    """Per-Gaussian labels and per-object selections.

    Attributes:
        labels: (N,) uint8 label of every Gaussian.
        objects: (M,) uint8 object IDs (mask labels other than 0).
        selections: (M, N) bool, Gaussians selected for each object.
        model: the fingerprint of the model labelled (:attr:`gsseg.run.loaded.Run.fingerprint`),
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

    @classmethod
    def of_labels(cls, labels: np.ndarray, method: str, gamma_p: float = 0.0) -> Segmentation:
        """The segmentation whose objects are the labels other than 0 in ``labels`` (N,), each
        selecting the Gaussians that carry it, one label a Gaussian (``multi``; labels made
        elsewhere: by hand, by a test)."""
        labels = np.asarray(labels).astype(np.uint8)
        objects = np.unique(labels[labels > 0])
        return cls(labels, objects, labels[None, :] == objects[:, None], method, "multi", gamma_p)

    def relabelled(self, labels: np.ndarray, objects: np.ndarray | None = None, **changes) -> Segmentation:
        """A copy with new (N,) ``labels`` (and (M',) ``objects``, where given), the selections
        made from them, and ``changes`` to the other fields."""
        objects = self.objects if objects is None else objects
        labels = np.asarray(labels).astype(np.uint8)
        return replace(self, labels=labels, objects=objects, selections=labels[None, :] == objects[:, None], **changes)

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


@dataclass(frozen=True)
class _Votes:
    """What every method and mode reads: the contributions normalised per Gaussian and the
    prior placed on them.

    Attributes:
        labels: (K,) int64 mask label of each row of ``share``.
        share: (K, N) each Gaussian's share of its blended weight per label.
        observed: (N,) bool Gaussians some view saw.
        objects: (M,) uint8 the labels other than 0.
        prior_row: (N,) int64 the row of each Gaussian's prior label, -1 where no row has it.
        bonus: (N,) gamma_p * p(i, l_i).
    """

    labels: np.ndarray
    share: torch.Tensor
    observed: torch.Tensor
    objects: np.ndarray
    prior_row: torch.Tensor
    bonus: torch.Tensor

    @property
    def object_ids(self) -> torch.Tensor:
        return torch.as_tensor(self.objects.astype(np.int64))


def _votes(
    contributions: Contributions, prior_labels: torch.Tensor, prior_probs: torch.Tensor, gamma_p: float
) -> _Votes:
    labels = contributions.labels.astype(np.int64)
    share, observed = normalize(contributions.weights)
    # The row of each Gaussian's prior label l_i in A (-1 where no mask shows that label):
    # the prior touches one entry per Gaussian, so it is added there, not as a (K, N) matrix.
    row_of = torch.full((256,), -1, dtype=torch.int64)
    row_of[torch.as_tensor(labels)] = torch.arange(len(labels))
    return _Votes(
        labels=labels,
        share=share,
        observed=observed,
        objects=contributions.labels[contributions.labels > 0],
        prior_row=row_of[prior_labels.clamp(0, 255)],
        bonus=gamma_p * prior_probs,
    )


def _classifier_labels(votes: _Votes, prior_labels: torch.Tensor, options: LabelOptions) -> torch.Tensor:
    """(N,) l_i alone."""
    return prior_labels.clamp(0, 255)


def _multi_labels(votes: _Votes, prior_labels: torch.Tensor, options: LabelOptions) -> torch.Tensor:
    """(N,) the argmax over labels (Eq. 9 of the paper): of A plus the prior at l_i
    (``prior``), or of A with ``slack`` added to the background (``flashsplat``). Unobserved
    Gaussians keep l_i (``prior``) or take 0 (``flashsplat``)."""
    score, labels = votes.share, votes.labels
    if options.method == "prior":
        has_row = torch.nonzero(votes.prior_row >= 0).squeeze(1)
        score[votes.prior_row[has_row], has_row] += votes.bonus[has_row]
    elif len(labels) and labels[0] == 0:
        score[0] += options.slack
    n = score.shape[1]
    best = torch.as_tensor(labels)[score.argmax(dim=0)] if len(labels) else torch.zeros(n, dtype=torch.int64)
    fallback = prior_labels if options.method == "prior" else torch.zeros_like(prior_labels)
    return torch.where(votes.observed, best, fallback)


def _binary_selections(votes: _Votes, options: LabelOptions) -> torch.Tensor:
    """(M, N) bool one object at a time: its share against the rest, plus the prior (or
    ``slack`` under ``flashsplat``) on the rest's side, except in the row of l_i, where the
    prior sides with the object. Unobserved Gaussians are selected by their l_i alone."""
    first = int(votes.labels[0] == 0) if len(votes.labels) else 0  # object rows start after label 0
    fg = votes.share[first:]
    rest = torch.sub(1.0, fg)
    rest += (votes.bonus if options.method == "prior" else torch.full_like(votes.bonus, options.slack))[None, :]
    selections = fg > rest
    mine = torch.zeros_like(selections)
    if options.method == "prior":
        has_row = torch.nonzero(votes.prior_row >= 0).squeeze(1)
        on_obj = has_row[votes.prior_row[has_row] >= first]
        r = votes.prior_row[on_obj] - first
        selections[r, on_obj] = fg[r, on_obj] + votes.bonus[on_obj] > 1.0 - fg[r, on_obj]
        mine[r, on_obj] = True
    return torch.where(votes.observed[None, :], selections, mine)


def _last_selecting(selections: torch.Tensor, object_ids: torch.Tensor) -> torch.Tensor:
    """(N,) the last object in ID order whose (M, N) ``selections`` hold each Gaussian; 0
    where none does."""
    if not len(object_ids):
        return torch.zeros(selections.shape[1], dtype=torch.int64)
    # the largest 1-based row number that selects (uint8 holds it: at most 255 objects)
    rank = torch.arange(1, len(object_ids) + 1, dtype=torch.uint8)[:, None]
    last = (selections.to(torch.uint8) * rank).amax(dim=0).long()
    return torch.where(last > 0, object_ids[(last - 1).clamp_min(0)], 0)


def reassign(
    contributions: Contributions,
    prior_labels: torch.Tensor,
    prior_probs: torch.Tensor,
    options: LabelOptions = LabelOptions(),
) -> Segmentation:
    """Labels of every Gaussian (the 3D regularisations of ``options`` are applied after it,
    :func:`gsseg.segment.segment_run.label_gaussians`).

    Args:
        contributions: A (K, N) over the mask labels.
        prior_labels, prior_probs: (N,) l_i and p(i, l_i) from :func:`classifier_prior`.
        options: ``method``: ``prior`` (A + gamma_p p(i, l_i) [l = l_i], the default),
            ``flashsplat`` (A with ``slack`` added to the background's share), ``classifier``
            (l_i alone). ``mode``: ``multi``: argmax over labels (Eq. 9 of the paper);
            ``binary``: one object at a time, object share against the rest (plus the prior
            on whichever side l_i is), so selections may overlap; ``labels`` then give each
            Gaussian the last object (in ID order) that selected it. ``gamma_p``: the prior's
            weight, any real number.
    """
    votes = _votes(contributions, prior_labels, prior_probs, options.gamma_p)
    ids = votes.object_ids
    if options.method == "classifier" or options.mode == "multi":
        rule = _classifier_labels if options.method == "classifier" else _multi_labels
        labels = rule(votes, prior_labels, options)
        selections = labels[None, :] == ids[:, None]
    else:
        selections = _binary_selections(votes, options)
        labels = _last_selecting(selections, ids)
    return Segmentation(
        labels=labels.numpy().astype(np.uint8),
        objects=votes.objects,
        selections=selections.numpy(),
        method=options.method,
        mode=options.mode,
        gamma_p=options.gamma_p,
    )
