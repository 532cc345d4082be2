"""Selections made by clicks, each for or against, whatever the labels hold.

A click is the set of Gaussians seen at the clicked pixel, each with its blended weight there
(:func:`gsseg.segment.prompts.click_evidence`); the Gaussians that carry most of that weight are
its seeds. The selection is a cut over a graph of the Gaussians (each joined to its nearest
neighbours; an edge is strong between Gaussians of like colour and object feature) made by a
max-flow solver (PyMaxflow), with a cost per Gaussian from six kinds of evidence:

- **the views** (the first positive click): in every training view where the click's Gaussians
  are seen, the mask region they fall in (of each mask layer: the masks that voted and the
  masks the run was trained on, :class:`gsseg.render.contributions.RegionWeights`) is the
  object's; a Gaussian whose blended weight falls mostly in the object's regions, over the
  views that show the object, is likely the object. Regions the selection then covers for the
  most part join it, and the vote is taken again (:attr:`ClickOptions.iterations`). This is the
  multi-view lifting of interactive 3D segmentation, with the weight-free masks in place of
  SAM's: each view errs on its own, and the vote follows the views that agree. An object the
  3D labels joined to its support, or that no label holds, is found as long as the views hold
  it apart;
- **the labels**: the label under the first click's seeds, a prior of the views' vote, in
  proportion to how far it agrees with the vote (a label that swallowed the table under the
  object disagrees with it) and worth the weight of a typical Gaussian in the views: it
  decides for the Gaussians the views see little of, and the views for those they see much of;
- **the colours** (:class:`ColourModel`): as GrabCut learns the colours of the object and of the
  rest from its last cut and cuts again, colour histograms of the selected Gaussians the views
  vote in firmly and of the unselected ones (:attr:`ClickOptions.appearance_rounds`); where the
  masks split an object (the back of a head that the views give to the table), its colour
  carries the cut across the split, and where the views are sure they outweigh it;
- **the selection before the click** (from the second click on): a click changes the
  selection only where its evidence outweighs :attr:`ClickOptions.stickiness`, and only its
  way: a positive click adds to the selection and takes nothing out, a negative click takes
  out and adds nothing, and only from its side of the graph (the Gaussians nearer its seeds
  than any positive seed), and there only what its word reaches, not what the views alone
  hold off (a part a positive click grew against them), so that a click never undoes what
  the earlier clicks fixed;
- **a negative click**: over the Gaussians nearer, along the graph (edge lengths from
  position, colour and feature), to its seeds than to any positive seed, in proportion to how
  much nearer, the click's word replaces the rest (:meth:`GaussianGraph.split`): a part the
  views and labels joined to the object goes, while the object's own Gaussians beside the
  click, nearly as near to a positive seed, keep their evidence, and so do those the views
  hold to the object more firmly than the clicked part (:meth:`ClickSelector._yielding`: a
  spill beside a head goes, the top of the head next to it stays); it reaches only what
  its view shows (:meth:`ClickSelector._in_sight`: the back of the head stays), and only
  what looks more like the clicked part than like the selection
  (:meth:`ClickSelector._alike`: a green floater beside a bronze head goes, the head's side
  next to it stays). On a part the masks joined to the object, of a colour the object does not
  have (:meth:`ClickSelector._apart`: the table under the tools), it carves the part apart
  on the negative clicks' side of the graph, as the clicks do where the masks hold the scene
  (below), what its view hides too. On the selection's blurred rim, whose pixel its selected
  and unselected seeds share (:meth:`ClickSelector._on_edge`: the seeds it pins, or all of
  them, a large hazy Gaussian of the object among them), it takes out only those of
  its seeds of the rest's colours (:meth:`ClickSelector._edge_moved`), and so it does where
  it lands on what the selection draws within its seeds' blur of the edge of it
  (:meth:`ClickSelector._in_blur`: a model fitted no sharper than its photos draws a head's
  rim a few pixels beyond the head, with the head's own Gaussians);
- **a later positive click**, the same mirrored (:meth:`ClickSelector._grown`; on the rim it
  adds only those of its seeds of the selection's colours, so that what a negative click took
  out beside the rim stays out): over the
  Gaussians nearer, along the graph, to its seeds that lie beside the selection than to those
  the views hold off the object, the click's word replaces the rest, where its view shows
  them and they look like the clicked part: a highlight on a bronze head that the masks hold
  as a region of its own comes in whole. A click whose seeds lie mostly away from the
  selection, deep inside a part the masks gave to the surroundings (a box's lid joined to
  the bench under it), grows its part up to the Gaussians held off whose colour the object
  does not have, what its view hides of the part too, and only what the graph joins to the
  selection (an object is one piece: a box of the object's colour whose edge draws a pixel
  of the object's rim stays out, :meth:`GaussianGraph.joined`). Its seeds leave out the
  large hazy Gaussians the views see much of (:meth:`ClickSelector._hazy`): a click on a
  head's rim where such a Gaussian shows does not bring the blur it draws beside the head;
  where all its seeds are heavy in the views, those of them not many times the median size
  that it lands on more than a sliver of stay (:meth:`ClickSelector._pinned`: an object near
  the camera, not the floor a heavy Gaussian draws beside a head's cheek). Once a negative
  click carved a part apart, the seeds of a later positive click off the selection whose colour
  the object lacks and the negative clicks' seeds have (:meth:`ClickSelector._unlike`) are
  not pinned: a click on the object's rim whose pixel the ground carved off beside it draws
  does not bring the ground back.

Where the views' vote of the first click holds the scene (masks that read the object and its
surroundings as one region: :meth:`RegionVote.holds_the_scene`), neither the views nor the
labels say where the object ends. Where the vote holds even the border of the clicked view
(:attr:`ClickOptions.frame_held`: masks that say nothing), the view's frame does, as a box's
does in GrabCut: the first click is cut from the Gaussians drawn along the view's border
(:meth:`ClickSelector._framed`), and each later click moves the selection's edge by its seeds
where it lands on that edge (positive, where that adds none of them, it carves the part the
first cut missed from those a few spacings beyond the edge: :meth:`ClickSelector._missed`),
or carves its own cell, or, positive and of a colour the frame
holds (the object reaches the view's border there), cuts the object again from all the
clicks' seeds (:meth:`ClickSelector._reframed`).
Elsewhere (an object that fills most of every view, its masks saying where it ends), from
the first negative click on a part the vote holds
firmly (:meth:`ClickSelector._firm`: the masks joined it to the object) the clicks carve it
alone (:meth:`ClickSelector._carved`): the graph's geodesic split between the positive and
negative seeds, colour models learned from the cut, and each click changing only its own cell
(the first to carve: the cells of all negative clicks so far) and what no click's view shows
(:meth:`ClickSelector._unseen`), which every cut decides. A negative click on what the vote
holds loosely (the spill of an object that fills most of every view, drawn over the
background beside it) is a negative click as with masks: there the vote does say where the
object ends.

The seeds are hard constraints; the source's side of the cut is the selection (parts apart
in space, several objects under one mask, stay together where the views join them). A later
positive click adds its seeds, what the cut joins to them and the part it grows. Where it
lands on what the vote holds off the object (a part the first click's vote missed), the
regions under it that lie beside the selection also join the vote, raising it and lowering it
nowhere (:meth:`ClickSelector.views_vote`). A region the masks joined to the selection (a
statue's head and the bush behind it) stays out of the vote, and so do the regions under a
click on what the vote gives the object in part (a statue's shoulder, whose pixels the other
views' masks give to the bush beside it).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import maxflow
import numpy as np
import scipy.sparse as sp
from scipy import ndimage
from scipy.sparse.csgraph import connected_components, dijkstra
from scipy.spatial import cKDTree
from skimage.color import rgb2lab

from dataset_tools.infra.errors import InputError, OptionError
from gsseg.model.gaussians import Gaussians
from gsseg.render.contributions import SCENE_SHARE, SCENE_VIEWS, RegionWeights

HARD = 1e9  # the capacity that pins a seed to its side of the cut


class SceneHeld(UserWarning):
    """The masks hold the clicked object and its surroundings as one region: the clicks alone say
    where the object ends (:meth:`ClickSelector.holds_the_scene`)."""


@dataclass(frozen=True)
class Click:
    """Pixel (u, v) of the view named ``view``, for (``positive``) or against the selection."""

    view: str
    u: float
    v: float
    positive: bool = True


@dataclass(frozen=True)
class ClickOptions:
    """The constants of the click cut (docs/segmentation.md, "Clicks").

    Attributes:
        neighbours: each Gaussian's edges to its nearest Gaussians.
        region_share: a mask region is the object's once the selection carries this share of
            its weight.
        iterations: rounds of the views' vote.
        seen_share: a click is seen in a view where its Gaussians show at least this share of
            the weight they show in the view that shows them most; a later click lands on the
            selection's edge where its selected seeds and the others each hold at least this
            share of its seeds' weight (:meth:`ClickSelector._on_edge`), and lands on the
            selection in part where its selected seeds hold this share
            (:meth:`ClickSelector._beside`).
        seed_share: the seeds are the Gaussians carrying this share of the click's weight ...
        seed_local: ... of those with at least this share of their weight in the clicked view
            at the click (:meth:`ClickEvidence.seeds`).
        hold_share: where a mask layer's regions under the first click hold, in the median
            over its views, at least this share of the click's weight, the layers that hold
            less do not vote (a pass that left the object in the background, or in slivers,
            beside one that holds it); a round of the vote adds regions in the views where
            they hold at least this share of the selection's weight.
        evidence: weight of the views' vote (times its log-odds).
        label_prior: the label under the first click is a prior share of one half plus (on the
            label) or minus (off it) this ...
        label_strength: ... worth this many times the median Gaussian's weight in the views,
            where the label agrees with the vote.
        overlap: a later positive click's region joins the vote where it holds under this share
            of the selection's weight in its view (a part beside the object; a region the
            masks joined to the object would bring what they joined).
        part_share: ... and where it holds this share of the click's weight in that view (the
            click lies on it, not beside it).
        split_weight: weight of a negative click over the Gaussians on its side, and of a
            later positive click over its part's (:meth:`ClickSelector._grown`).
        split_full: how far on a negative click's side (:meth:`GaussianGraph.split`) its word
            replaces all else (0.5: three times as near to it as to a positive click); the
            same for a later positive click's part.
        part_reach: a later positive click grows a part from its seeds that lie within this
            many times the Gaussians' median spacing of a selected one (a part beside it),
            where these hold most of its unselected seeds' weight; where the frame bounds the
            object, it pins no seed beyond it (:meth:`ClickSelector._beside`).
        missed_reach: where such a click on the edge of a selection the frame bounds adds none
            of its seeds, it carves the part the first cut missed from its unselected seeds
            within this many spacings of a selected one (:meth:`ClickSelector._missed`); where
            the selection draws a sliver of its pixel, it pins its seeds within this reach
            (:meth:`ClickSelector._beside`).
        off_share: ... up to the Gaussians the views hold off the object (unselected, with
            under this share of their weight in the object's regions, ...
        off_weight: ... or under one half of a weight at least this many times the median
            Gaussian's: large hazy ones seen much) or a negative click's seeds; such hazy
            Gaussians are no seeds of a later positive click (:meth:`ClickSelector._hazy`),
            unless all its seeds are (:meth:`ClickSelector._pinned`).
            The regions under a later positive click join the vote only where its seeds'
            share is under ``off_share`` (:meth:`ClickSelector.views_vote`).
        large_size: Gaussians whose longest axis is at least this many times the median
            Gaussian's count as hazy too, and a later positive click adds none of them
            (:meth:`ClickSelector.cut`).
        sliver: where all of a later positive click's seeds are hazy, it pins those that carry
            at least this share of their weight in the clicked view at the click
            (:attr:`ClickEvidence.local`): what it lands on of the rest is a sliver of what
            they draw (:meth:`ClickSelector._pinned`).
        far_colour: where most of a later positive click's seeds lie beyond ``part_reach``
            (a part the masks gave to the surroundings, clicked deep inside), its part is
            bounded only by the Gaussians the views hold off the object whose colour is at
            least this many log-units likelier under the rest's colours than under the
            object's (:class:`ColourModel`, clipped at 3: colours the object does not have).
        against_margin: on a negative click's side, a Gaussian the views hold to the object
            by twice this share more firmly than the clicked part keeps its evidence
            (:meth:`ClickSelector._yielding`).
        shown_share: a negative click reaches a Gaussian its view shows this much of
            (:attr:`ClickEvidence.shown`), in part one shown less (:meth:`ClickSelector._in_sight`).
        against_colour: a negative click reaches no Gaussian whose colour is this many
            log-units likelier under the selection's colours than under the clicked part's
            (:meth:`ClickSelector._alike`).
        carve_share: where the first click's vote holds the scene, the clicks carve from the
            first negative click whose seeds the vote holds by at least this share
            (:meth:`ClickSelector._firm`).
        apart_colour: elsewhere, a negative click whose seeds the vote holds by at least
            ``carve_share`` (the masks joined the clicked part to the object) and whose colour
            lies at least this far (CIE76 distance in Lab) from every positive seed's carves
            its part out (:meth:`ClickSelector._apart`).
        rim_spread: a later negative click lands on the selection's blurred rim where it lies
            on what the selection draws in its view within this many times its seeds' footprint
            (their weighted standard deviation) of the edge of what it draws
            (:meth:`ClickSelector._in_blur`; 0: never).
        stickiness: weight of the selection before the click; under a negative click, the
            least cost of a selected Gaussian (it goes by the click's word alone).
        carve_stickiness: the same where the clicks carve the object alone
            (:meth:`ClickSelector._carved`).
        frame_held: where the first click's vote holds the scene and this share of the weight
            of its view's frame (masks that say nothing, not even of the view's border), the
            click is cut from the frame (:meth:`ClickSelector._framed`).
        smoothness: weight of the graph's edges.
        appearance_rounds: rounds of the colour models (:class:`ColourModel`), each learned from
            the cut before it (0: none).
        appearance_weight: weight of the colour models' log-likelihood ratio.
        appearance_bins: bins per channel of the colour histograms (CIE Lab).
        appearance_firm: the object's colours are learned from the Gaussians the cut selects
            that the views vote in by at least this share (a spill the cut took along does not
            teach them).
    """

    neighbours: int = 10
    region_share: float = 0.5
    iterations: int = 3
    seen_share: float = 0.2
    seed_share: float = 0.8
    seed_local: float = 0.001
    hold_share: float = 0.1
    evidence: float = 2.0
    label_prior: float = 0.4
    label_strength: float = 1.0
    overlap: float = 0.05
    part_share: float = 0.5
    split_weight: float = 4.0
    split_full: float = 0.5
    part_reach: float = 3.0
    missed_reach: float = 9.0
    off_share: float = 0.05
    off_weight: float = 16.0
    large_size: float = 8.0
    sliver: float = 0.05
    far_colour: float = 3.0
    against_margin: float = 0.2
    shown_share: float = 0.1
    against_colour: float = 1.0
    carve_share: float = 0.6
    apart_colour: float = 10.0
    rim_spread: float = 0.75
    stickiness: float = 3.0
    carve_stickiness: float = 0.75
    frame_held: float = 0.9
    smoothness: float = 1.0
    appearance_rounds: int = 2
    appearance_weight: float = 1.0
    appearance_bins: int = 12
    appearance_firm: float = 0.6

    def __post_init__(self) -> None:
        if not 0 <= self.label_prior < 0.5 or self.label_strength < 0:
            raise OptionError(
                "{label_prior}: give a share in [0, 0.5); {label_strength}: 0 or more.",
                label_prior=self.label_prior,
                label_strength=self.label_strength,
            )
        if self.neighbours < 1 or self.iterations < 1:
            raise OptionError("{neighbours} and {iterations}: give 1 or more.", neighbours=self.neighbours)
        if self.against_colour <= 0 or self.far_colour <= 0:
            raise OptionError(
                "{against_colour} and {far_colour}: give a number of log-units above 0.",
                against_colour=self.against_colour,
                far_colour=self.far_colour,
            )
        if self.apart_colour <= 0:
            raise OptionError("{apart_colour}: give a colour distance above 0.", apart_colour=self.apart_colour)
        if self.rim_spread < 0:
            raise OptionError("{rim_spread}: give 0 (no such rim) or more.", rim_spread=self.rim_spread)
        if self.appearance_rounds < 0 or self.appearance_bins < 2:
            raise OptionError(
                "{appearance_rounds}: give 0 or more; {appearance_bins}: 2 or more.",
                appearance_rounds=self.appearance_rounds,
                appearance_bins=self.appearance_bins,
            )
        for name in (
            "region_share",
            "seen_share",
            "seed_share",
            "seed_local",
            "hold_share",
            "overlap",
            "part_share",
            "against_margin",
            "shown_share",
            "appearance_firm",
            "carve_share",
            "frame_held",
            "sliver",
        ):
            if not 0 < getattr(self, name) <= 1:
                raise OptionError(f"{{{name}}}: give a share in (0, 1].", **{name: getattr(self, name)})


@dataclass(frozen=True)
class ClickEvidence:
    """What one click saw: ``weights`` (N,) each Gaussian's blended weight at the clicked
    pixels, whether the click is for (``positive``) or against the selection, ``shown``
    (N,) in [0, 1] how much of each Gaussian the clicked view shows (its blended weight over
    the view over what it would give unoccluded), and ``local`` (N,) in [0, 1] the share of
    its blended weight in the view that falls at the clicked pixels, ``frame`` (N,) its blended
    weight over the view's frame, the pixels along its border, ``spread`` (N,) the standard
    deviation of its footprint in the view along its longest axis, in pixels, and ``inside``,
    which gives for a selection ((N,) bool) how far the clicked pixel lies inside what the
    selection draws in the view (pixels to the nearest one it does not win; 0 where it does not
    win the clicked one) (all None: a prompt without a view, a 3D point)."""

    weights: np.ndarray
    positive: bool
    shown: np.ndarray | None = None
    local: np.ndarray | None = None
    frame: np.ndarray | None = None
    spread: np.ndarray | None = None
    inside: Callable[[np.ndarray], float] | None = None

    def seeds(self, share: float, least_local: float = 0.0) -> np.ndarray:
        """Indices of the Gaussians that carry ``share`` of the click's weight, heaviest first,
        of those with at least ``least_local`` of their weight in the view at the click (all
        of them where none has): a large Gaussian of the backdrop that shows behind a thin
        part at the click, and over much of the view elsewhere, is not what was clicked."""
        weights = self.weights
        if self.local is not None and (weights * (self.local >= least_local)).sum() > 0:
            weights = weights * (self.local >= least_local)
        order = np.argsort(-weights, kind="stable")
        cumulative = np.cumsum(weights[order])
        return order[: int(np.searchsorted(cumulative, share * cumulative[-1])) + 1]


@dataclass(frozen=True)
class GaussianGraph:
    """Each Gaussian joined to its nearest ones: edges ``a`` -> ``b`` (E,), their ``affinity``
    (E,) in (0, 1] (like colour and feature, near), their ``length`` (E,) along which a
    click's side reaches (distance, colour and feature differences, each over its median), and
    the Gaussians' median ``spacing``."""

    a: np.ndarray
    b: np.ndarray
    affinity: np.ndarray
    length: sp.csr_matrix
    spacing: float  # the median distance between a Gaussian and its nearest neighbour

    @classmethod
    def of(cls, gaussians: Gaussians, neighbours: int) -> GaussianGraph:
        means = gaussians.means.detach().cpu().numpy().astype(np.float64)
        n, k = len(means), min(neighbours, len(means) - 1)
        if k < 1:
            empty = np.zeros(0, np.int64)
            return cls(empty, empty, np.zeros(0), sp.csr_matrix((n, n)), 0.0)
        colours = gaussians.base_colours.detach().cpu().numpy()
        features = gaussians.obj_feat.detach().cpu().numpy().astype(np.float64)
        dist, nbr = cKDTree(means).query(means, k=k + 1, workers=-1)
        spacing = float(np.median(dist[:, 1]))
        a, b = np.repeat(np.arange(n), k), nbr[:, 1:].ravel()
        lo, hi = np.minimum(a, b), np.maximum(a, b)
        _, first = np.unique(lo * n + hi, return_index=True)  # each undirected edge once
        a, b, dist = lo[first], hi[first], dist[:, 1:].ravel()[first]

        def scaled(x: np.ndarray) -> np.ndarray:
            return x / max(float(np.median(x)), 1e-12)

        d = scaled(dist)
        c = scaled(np.linalg.norm(colours[a] - colours[b], axis=1))
        f = scaled(np.linalg.norm(features[a] - features[b], axis=1))
        length = sp.coo_matrix((d + 2 * (c + f) + 1e-9, (a, b)), shape=(n, n)).tocsr()
        return cls(a, b, np.exp(-(c**2 + f**2) / 4) / (1 + d), length, spacing)

    def distances(self, sources: np.ndarray) -> np.ndarray:
        """(N,) each Gaussian's distance along the graph to the nearest of ``sources`` (S,)
        (inf where none is reached, or there is none)."""
        if not len(sources):
            return np.full(self.length.shape[0], np.inf)
        return dijkstra(self.length, directed=False, indices=sources, min_only=True)

    def joined(self, part: np.ndarray, to: np.ndarray) -> np.ndarray:
        """(N,) bool: the Gaussians of ``part`` (N,) bool joined by the graph's edges, through
        ``part`` and ``to`` (N,) bool alone, to a Gaussian of ``to``."""
        n, nodes = len(part), part | to
        inside = nodes[self.a] & nodes[self.b]
        edges = sp.coo_matrix((np.ones(int(inside.sum())), (self.a[inside], self.b[inside])), shape=(n, n))
        component = connected_components(edges, directed=False)[1]
        return part & np.isin(component, component[to])

    def split(self, negative: np.ndarray, positive: np.ndarray) -> np.ndarray:
        """(N,) in [0, 1]: how far each Gaussian lies on the side of the ``negative`` seeds,
        (d+ - d-) / (d+ + d-) with d+ and d- its distances along the graph to the nearest
        positive and negative seed; 0 where it is nearer a positive one, 1 where no positive
        one is reached."""
        far, near = self.distances(positive), self.distances(negative)
        side = near < far
        with np.errstate(invalid="ignore"):
            ratio = np.where(np.isinf(far), 1.0, (far - near) / np.maximum(far + near, 1e-12))
        return np.where(side, ratio, 0.0)


class RegionVote:
    """The views' vote over :class:`RegionWeights`: which Gaussians fall in the regions of an
    object, over the views (of each mask layer) that show it."""

    def __init__(self, regions: RegionWeights):
        self.matrix = regions.matrix.tocsr().astype(np.float64)
        self.by_gaussian = self.matrix.T.tocsr()
        self.label = regions.label
        self.layer = regions.layer
        self.row_sums = np.asarray(self.matrix.sum(1)).ravel()
        # A vote unit is one view of one mask layer.
        _, self.unit = np.unique(
            regions.layer.astype(np.int64) * (int(regions.view.max(initial=0)) + 1) + regions.view, return_inverse=True
        )
        self.n_units = int(self.unit.max(initial=-1)) + 1
        self.units = sp.csr_matrix(
            (np.ones(len(self.unit)), (np.arange(len(self.unit)), self.unit)), shape=(len(self.unit), self.n_units)
        )
        self.unit_totals = self.units.T @ self.row_sums  # (U,) all the weight each unit shows

    def clicked_regions(
        self,
        click: ClickEvidence,
        seen_share: float,
        hold: float = 0.0,
        any_label: bool = False,
        layer_hold: float = 0.0,
    ) -> np.ndarray:
        """(R,) bool: in each vote unit where the click is seen (its Gaussians' weight there is
        at least ``seen_share`` of their weight in the unit where it is largest), the object
        region (not the background, label 0, unless ``any_label``) holding most of that
        weight, where it holds at least ``hold`` of it; where some mask layer's regions hold,
        in the median over its units that see the click, at least ``layer_hold`` of it, only
        such layers (a pass that left the object in the background, or in slivers, beside one
        that holds it, does not speak of it)."""
        weight = self.matrix @ click.weights
        per_unit = self.units.T @ weight
        ranked = weight if any_label else np.where(self.label != 0, weight, -1.0)
        order = np.lexsort((-ranked, self.unit))
        best = order[np.unique(self.unit[order], return_index=True)[1]]
        seen = per_unit[self.unit[best]] >= seen_share * max(float(per_unit.max(initial=0)), 1e-12)
        out = np.zeros(len(weight), bool)
        holds = weight[best] / np.maximum(per_unit[self.unit[best]], 1e-12)
        chosen = seen & (holds >= hold) & ((self.label[best] != 0) | any_label) & (weight[best] > 0)
        layer = self.layer[best]
        layers = np.unique(layer[seen])
        loud = np.array([np.median(holds[seen & (layer == k)]) >= layer_hold for k in layers], bool)
        if loud.any():
            chosen &= np.isin(layer, layers[loud])
        out[best[chosen]] = True
        return out

    def shares(self, inside: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Each Gaussian's share of its weight that falls in the ``inside`` (R,) regions, over
        the vote units holding one (N,), and that weight (N,) (0: no such unit sees it)."""
        units_on = (self.units.T @ inside.astype(np.float64)) > 0
        held = self.by_gaussian @ inside.astype(np.float64)
        total = self.by_gaussian @ units_on[self.unit].astype(np.float64)
        seen = total > 0
        return np.where(seen, held / np.where(seen, total, 1.0), 0.0), total

    def apart_from(self, regions: np.ndarray, selected: np.ndarray, overlap: float) -> np.ndarray:
        """(R,) bool: those of ``regions`` that hold under ``overlap`` of the ``selected`` (N,)
        Gaussians' weight in their vote unit (a part beside the selection, not one the masks
        joined to it)."""
        held = self.matrix @ selected.astype(np.float64)
        per_unit = self.units.T @ held
        return regions & (held < overlap * per_unit[self.unit])

    def holds_the_scene(self, share: np.ndarray, click: ClickEvidence, seen_share: float) -> bool:
        """Whether the Gaussians a vote holds (``share`` (N,) above one half) cover most of every
        view: :data:`~gsseg.render.contributions.SCENE_SHARE` of the blended weight in
        :data:`~gsseg.render.contributions.SCENE_VIEWS` of the vote units where ``click`` is
        seen (its weight there at least ``seen_share`` of its largest). Masks that hold the
        object and its surroundings as one region give such a vote: it says nothing of where
        the object ends."""
        held = self.units.T @ (self.matrix @ (share > 0.5).astype(np.float64))
        clicked = self.units.T @ (self.matrix @ click.weights)
        seen = clicked >= seen_share * max(float(clicked.max(initial=0)), 1e-12)
        wide = held >= SCENE_SHARE * np.maximum(self.unit_totals, 1e-12)
        return bool(seen.any() and (wide & seen).sum() >= SCENE_VIEWS * seen.sum())

    def vote(self, clicked: np.ndarray, options: ClickOptions) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(N,) each Gaussian's share of weight in the object's regions, starting from the
        ``clicked`` (R,) ones, and (N,) the weight the share is of (0: not seen where the
        object is), after :attr:`ClickOptions.iterations` rounds; and (R,) the object's regions
        the last round counted. A round adds the regions the selection (share above one half)
        covers for more than :attr:`ClickOptions.region_share`, in the vote units where they
        hold at least :attr:`ClickOptions.hold_share` of the selection's weight: a view whose
        masks leave the object in the background does not count it against the object."""
        inside = clicked
        for _ in range(options.iterations):
            share, weight = self.shares(inside)
            held = self.matrix @ (share > 0.5)
            covered = (held / np.maximum(self.row_sums, 1e-12) > options.region_share) & (self.label != 0)
            holding = (self.units.T @ (held * covered)) >= options.hold_share * (self.units.T @ held)
            counted = inside
            inside = clicked | (covered & holding[self.unit])
        return share, weight, counted


class ColourModel:
    """The colours of a set of Gaussians as a smoothed histogram over CIE Lab (L over [0, 100],
    a and b over [-60, 60], ``bins`` per channel, smoothed by one bin), each Gaussian counted by
    its opacity: the appearance model of GrabCut, over the Gaussians of a cut rather than the
    pixels of a box. Dark bronze and dark green lie in neighbouring RGB bins but apart in a and
    b.

    Args:
        colours: (N, 3) RGB in [0, 1]. opacities: (N,) in [0, 1].
    """

    LAB_RANGE = np.array([[0.0, -60.0, -60.0], [100.0, 60.0, 60.0]])
    CLIP = 3.0  # the log-likelihood ratio is clipped to +-CLIP: one colour never outweighs the views

    def __init__(self, colours: np.ndarray, opacities: np.ndarray, bins: int):
        lab = rgb2lab(np.asarray(colours, np.float64)[None])[0]
        self.lab = lab  # (N, 3) each Gaussian's colour in CIE Lab
        unit = (lab - self.LAB_RANGE[0]) / (self.LAB_RANGE[1] - self.LAB_RANGE[0])
        cell = np.minimum((np.clip(unit, 0.0, 1.0) * bins).astype(np.int64), bins - 1)
        self.bin = np.ravel_multi_index(cell.T, (bins,) * 3)  # (N,) each Gaussian's histogram bin
        self.opacities = np.asarray(opacities, np.float64)
        self.bins = bins

    def log_density(self, fit: np.ndarray) -> np.ndarray:
        """(N,) the log-density at each Gaussian's colour of the histogram of the ``fit`` (N,)
        bool Gaussians."""
        b = self.bins
        hist = np.bincount(self.bin[fit], self.opacities[fit], minlength=b**3).reshape(b, b, b)
        hist = ndimage.gaussian_filter(hist, 1.0, mode="constant")
        hist = hist / max(float(hist.sum()), 1e-12) + 1e-6 / b**3
        return np.log(hist.ravel()[self.bin])

    def ratio(self, inside: np.ndarray, outside: np.ndarray) -> np.ndarray:
        """(N,) log p(colour | inside) - log p(colour | outside), clipped to +-:attr:`CLIP`; 0
        where either set is empty (no colours to learn from)."""
        if not inside.any() or not outside.any():
            return np.zeros(len(self.bin))
        return np.clip(self.log_density(inside) - self.log_density(outside), -self.CLIP, self.CLIP)


def log_odds(p: np.ndarray) -> np.ndarray:
    p = np.clip(p, 0.02, 0.98)
    return np.log(p / (1 - p))


class ClickSelector:
    """Selections of one model by clicks (see the module docstring); the graph and the vote are
    built once, each click then costs one vote and one cut.

    Args:
        gaussians: the model. labels: (N,) its labels (0: background).
        regions: the region weights of the model (``RUN/regions.npz``).
    """

    def __init__(
        self, gaussians: Gaussians, labels: np.ndarray, regions: RegionWeights, options: ClickOptions = ClickOptions()
    ):
        if regions.matrix.shape[1] != len(gaussians) or len(labels) != len(gaussians):
            raise ValueError(
                f"{len(gaussians)} Gaussians, {len(labels)} labels and region weights of {regions.matrix.shape[1]}"
            )
        self.options = options
        self.labels = np.asarray(labels)
        self.means = gaussians.means.detach().cpu().numpy().astype(np.float64)
        longest = gaussians.log_scales.detach().cpu().numpy().max(1)  # (N,) log of each longest axis
        self.large = longest >= np.log(options.large_size) + float(np.median(longest))  # (N,) bool
        self.graph = GaussianGraph.of(gaussians, options.neighbours)
        self.vote = RegionVote(regions)
        self.colours = ColourModel(
            gaussians.base_colours.detach().cpu().numpy(),
            gaussians.opacities.detach().cpu().numpy(),
            options.appearance_bins,
        )

    def select(self, clicks: Sequence[ClickEvidence]) -> np.ndarray:
        """(N,) bool: the selection after ``clicks`` in order, each made from the one before.

        Raises:
            InputError: no positive click comes first.
        """
        if not clicks or not clicks[0].positive:
            raise InputError("a selection starts with a click on the object; click on it first.")
        selected = None
        for k in range(len(clicks)):
            selected = self.cut(clicks[: k + 1], selected)
        return selected

    def holds_the_scene(self, clicks: Sequence[ClickEvidence]) -> bool:
        """Whether ``clicks``, none of them against, began where the masks do not say where the
        object ends: the views' vote of the first holds the scene
        (:meth:`RegionVote.holds_the_scene`), as where the masks read the clicked object and its
        surroundings as one. The first click is then cut from its view's frame where the vote
        holds that too (:meth:`_framed`), and selects the scene elsewhere; from the first
        negative click on a part the vote holds firmly on (:meth:`_firm`), the clicks carve the
        object alone."""
        if not clicks or not all(click.positive for click in clicks):
            return False
        share, _, _ = self.views_vote(clicks[:1], None)
        return self.vote.holds_the_scene(share, clicks[0], self.options.seen_share)

    def cut(self, clicks: Sequence[ClickEvidence], before: np.ndarray | None) -> np.ndarray:
        """(N,) bool: the selection of ``clicks`` made from ``before``, the selection of all
        but the last of them (None for the first click): one step of :meth:`select`.

        A later positive click adds no Gaussian :attr:`ClickOptions.large_size` times the
        median size or more: such a Gaussian draws haze over what lies around the object,
        and the first click's cut, with the views' vote, decided it. With the clicks alone on
        DTU scan 24, alternating between two views, the ninth click re-cut the house from the
        frame and added 1 120 Gaussians, 988 of them the house's; 34 of the added were that
        large, and they painted the white table beside the house (mIoU 0.917 -> 0.847)."""
        if not clicks or not clicks[0].positive:
            raise InputError("a selection starts with a click on the object; click on it first.")
        selected = self._step(clicks, before)
        if before is not None and clicks[-1].positive:
            return before | (selected & ~self.large)
        return selected

    def _step(self, clicks: Sequence[ClickEvidence], before: np.ndarray | None) -> np.ndarray:
        """(N,) bool: :meth:`cut`'s selection before it leaves out the large Gaussians."""
        o = self.options
        last = clicks[-1].seeds(o.seed_share, o.seed_local)  # the last click's seeds, none pinned
        if before is not None and self._in_blur(clicks[-1], last, before):
            return self._edge_moved(clicks[-1], last, before)
        share, weight, voted_regions = self.views_vote(clicks, before)
        hazy = self._hazy(weight)
        seeds = [(c.seeds(o.seed_share, o.seed_local), c.positive) for c in clicks]
        seeds = [(self._pinned(clicks[i], k, hazy) if i and on else k, on) for i, (k, on) in enumerate(seeds)]
        positive = np.unique(np.concatenate([k for k, is_positive in seeds if is_positive]))
        negative = np.unique(np.concatenate([k for k, is_positive in seeds if not is_positive] or [[]]))
        negative = negative.astype(np.int64)
        both = np.intersect1d(positive, negative)
        positive, negative = np.setdiff1d(positive, both), np.setdiff1d(negative, both)
        own = np.setdiff1d(seeds[-1][0], both)  # the last click's seeds
        firm = self._firm(clicks) if before is not None and len(negative) else []
        scene = self.vote.holds_the_scene(share, clicks[0], o.seen_share)
        frame = self._frame(clicks[0], seeds[0][0], share) if scene else None
        if frame is not None:  # the clicks carve the object alone, framed by the first click's view
            if before is None:
                return self._framed(positive, frame)
            if clicks[-1].positive or firm:
                return self._reframed(clicks, seeds, frame, before)
        elif firm and scene:
            first = firm[0] == len(clicks) - 1
            return self._carved(clicks, own, positive, negative, before, first)
        if before is not None:  # a click on the selection's rim, by the seeds it pins or by all
            # of them (a hazy Gaussian of the object that draws the pixel is no seed it pins)
            for edge in (own, last):
                if self._on_edge(clicks[-1], edge, before):
                    return self._edge_moved(clicks[-1], edge, before)
        apart = self._apart(clicks, firm, seeds)
        if apart and apart[-1] == len(clicks) - 1:  # the masks joined the clicked part to the object
            within = self._yielding(clicks[-1:], own, voted_regions, share, weight > 0) > 0.5
            within &= self._alike(own, before) > 0
            return self._carved(clicks, negative, positive, negative, before, False, within)
        grown = np.zeros(len(self.labels))  # the last click's part, where it is a later positive one
        if before is not None:  # a later positive click pins only the seeds of the part it adds
            # once a part was carved apart, what looks like it and not like the object stays out
            held_off = np.flatnonzero(~before & self._unlike(before, negative)) if apart else []
            for i, (k, on) in enumerate(seeds):
                if i and on:
                    added = np.setdiff1d(k, negative)
                    part, pinned = self._grown(
                        clicks[i], np.setdiff1d(added, held_off), negative, share, weight, hazy, before
                    )
                    seeds[i] = (np.union1d(np.setdiff1d(k, added), pinned), on)
                    grown = part if i == len(clicks) - 1 else grown
            positive = np.setdiff1d(np.concatenate([k for k, is_positive in seeds if is_positive]), both)
        posterior = self._labelled(share, weight, seeds[0][0])
        cost = o.evidence * np.where(weight > 0, log_odds(posterior), -1.0)  # > 0: the object's
        if o.appearance_rounds:
            cost += o.appearance_weight * self._appearance(cost, positive, share >= o.appearance_firm)
        if before is not None:
            cost += o.stickiness * np.where(before, 1.0, -1.0)
            if clicks[-1].positive:  # deep in a later positive click's part its word outweighs all else
                cost = (1 - grown) * cost + o.split_weight * grown
            else:  # what the earlier clicks selected goes by this click's word alone, never the views'
                cost = np.where(before, np.maximum(cost, o.stickiness), cost)
        if len(negative):  # deep on a negative click's side its word outweighs all else
            side = np.clip(self.graph.split(negative, positive) / o.split_full, 0, 1)
            side *= self._yielding(clicks, negative, voted_regions, share, weight > 0)
            side *= self._in_sight(clicks)
            if before is not None:
                side *= self._alike(negative, before)
            cost = (1 - side) * cost - o.split_weight * side
        cut = self._min_cut(cost, positive, negative)
        if before is None:
            return cut
        if clicks[-1].positive:
            if apart:  # what a negative click carved apart comes back only nearer to a positive click
                carved = np.setdiff1d(np.concatenate([seeds[k][0] for k in apart]), positive)
                cut &= before | (self.graph.split(carved, positive) <= 0)
            return before | cut
        return before & (cut | (self.graph.split(own, positive) <= 0))  # only from its side

    def _labelled(self, share: np.ndarray, weight: np.ndarray, first_seeds: np.ndarray) -> np.ndarray:
        """(N,) the views' ``share`` (N,) with the label under the first click's seeds
        (``first_seeds``, indices) as its prior: a share of one half
        +- :attr:`ClickOptions.label_prior` (+ on the label, - off it) worth
        :attr:`ClickOptions.label_strength` times the median Gaussian's ``weight`` (N,) in the
        views, times how far the label agrees with the views' vote (a label that swallowed the
        table under the object disagrees with it and says nothing). A Gaussian the views see
        little of follows the label; one they see much of, as a large hazy Gaussian around
        the object drawing what lies behind it, follows the views."""
        o = self.options
        picked = np.setdiff1d(np.unique(self.labels[first_seeds]), [0])
        labelled = np.isin(self.labels, picked)
        voted = share > 0.5
        agree = (labelled & voted).sum() / max(int((labelled | voted).sum()), 1)
        trust = float(np.clip((agree - 0.5) / 0.4, 0, 1))
        prior = 0.5 + o.label_prior * np.where(labelled, 1.0, -1.0)
        seen = weight > 0
        strength = trust * o.label_strength * float(np.median(weight[seen])) if seen.any() else 0.0
        return (share * weight + strength * prior) / np.maximum(weight + strength, 1e-12)

    def views_vote(
        self, clicks: Sequence[ClickEvidence], before: np.ndarray | None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The views' vote of ``clicks`` (:meth:`RegionVote.vote`): (N,) each Gaussian's share of
        weight in the object's regions, (N,) the weight it is of (0: no view of the object
        sees it), (R,) the object's regions. The first click's regions start it; the regions
        under a later positive click on what the vote holds off the object (its seeds' share
        under :attr:`ClickOptions.off_share`: a highlight the masks hold as a region of its
        own, an object to join) that lie beside the selection ``before`` (N,) raise it where
        they speak and lower it nowhere: a part seen in views where the first click is not
        counts those views against the rest of the object, which the selection holds all the
        same. A click on what the vote gives the object in part (an edge the cut left out)
        speaks through the part it grows (:meth:`_grown`), not its regions: on a statue's
        shoulder beside a bush, the regions under it in the other views are the bush's."""
        o = self.options
        clicked = self.vote.clicked_regions(clicks[0], o.seen_share, layer_hold=o.hold_share)
        share, weight, regions = self.vote.vote(clicked, o)
        parts = np.zeros_like(clicked)
        for later in clicks[1:]:
            if later.positive and before is not None and self._held_off(later, share):
                under = self.vote.clicked_regions(later, o.seen_share, o.part_share)
                parts |= self.vote.apart_from(under, before, o.overlap)
        if (parts & ~clicked).any():
            more, more_weight, more_regions = self.vote.vote(clicked | parts, o)
            weight = np.where(more > share, more_weight, weight)
            share, regions = np.maximum(share, more), regions | more_regions
        return share, weight, regions

    def _gap(self, selected: np.ndarray, seeds: np.ndarray) -> np.ndarray:
        """(S,) each of the ``seeds`` (S,)' distance to the nearest Gaussian of ``selected`` (N,)
        bool (not empty)."""
        return cKDTree(self.means[selected]).query(self.means[seeds])[0]

    def _far_off(self, selected: np.ndarray, seeds: np.ndarray) -> bool:
        """Whether all of ``seeds`` (S,) lie farther from the ``selected`` (N,) bool Gaussians
        than the selection is wide (twice the 99th percentile of their distances from their
        mean): what a positive click lands on there is no part of the object but something
        apart from it, a floater in front of it or what shows through from far behind. With
        the clicks alone, a click on the statue in a second view whose pixel one black floater
        draws, 473 spacings from a selection 84 wide, cut the object again from the frame with
        it and added 3 513 Gaussians, 22 of them the statue's (mIoU 0.959 -> 0.274); the
        clicks that added parts of DTU's house, the statue and the head landed at most a fifth
        of the selection's width from it."""
        held = self.means[selected]
        width = 2.0 * float(np.quantile(np.linalg.norm(held - held.mean(0), axis=1), 0.99))
        return bool(self._gap(selected, seeds).min() > width)

    def _mask(self, indices: np.ndarray) -> np.ndarray:
        """(N,) bool: true at the Gaussians ``indices`` (S,)."""
        mask = np.zeros(len(self.labels), bool)
        mask[indices] = True
        return mask

    def _min_cut(self, cost: np.ndarray, positive: np.ndarray, negative: np.ndarray) -> np.ndarray:
        """(N,) bool: the source's side of the minimum cut of the graph's edges (times
        :attr:`ClickOptions.smoothness`) and the costs ``cost`` (N,) (> 0: the selection's), the
        ``positive`` and ``negative`` seeds pinned to their sides."""
        n = len(cost)
        graph = maxflow.Graph[float]()
        graph.add_nodes(n)
        edges = self.options.smoothness * self.graph.affinity
        graph.add_edges(self.graph.a, self.graph.b, edges, edges)
        source, sink = np.maximum(cost, 0.0), np.maximum(-cost, 0.0)
        source[positive], sink[negative] = HARD, HARD
        nodes = np.arange(n)
        graph.add_grid_tedges(nodes, source, sink)
        graph.maxflow()
        return ~graph.get_grid_segments(nodes)

    def _appearance(
        self, cost: np.ndarray, positive: np.ndarray, firm: np.ndarray, negative: np.ndarray | None = None
    ) -> np.ndarray:
        """(N,) the colour term of the cost, as GrabCut iterates its colour models: cut with
        ``cost`` (N,) and the colour term so far (the ``positive`` and ``negative`` seeds
        pinned), learn the object's colours from the selected Gaussians that are ``firm`` (N,)
        (those the views vote in firmly: at least :attr:`ClickOptions.appearance_firm`) and the
        rest's from the unselected, again for :attr:`ClickOptions.appearance_rounds`. Where the
        masks split an object (a head whose back the views give to the table), its colour
        carries the cut over the split; where the views are sure, they outweigh it."""
        o = self.options
        term = np.zeros_like(cost)
        negative = np.zeros(0, np.int64) if negative is None else negative
        for _ in range(o.appearance_rounds):
            selected = self._min_cut(cost + o.appearance_weight * term, positive, negative)
            term = self.colours.ratio(selected & firm, ~selected)
        return term

    def _carved(
        self,
        clicks: Sequence[ClickEvidence],
        clicked: np.ndarray,
        positive: np.ndarray,
        negative: np.ndarray,
        before: np.ndarray,
        first: bool,
        within: np.ndarray | None = None,
        framed: bool = False,
    ) -> np.ndarray:
        """(N,) bool: the selection after the last of ``clicks`` where the views' vote holds the
        scene (:meth:`RegionVote.holds_the_scene`), carved by the clicks alone, as seeded
        geodesic segmentation and GrabCut do without masks: each Gaussian is the object's in
        proportion to how much nearer, along the graph, it lies to a ``positive`` seed than to
        a ``negative`` one ((d- - d+) / (d- + d+), times :attr:`ClickOptions.split_weight`),
        with colour models learned from the cut (:meth:`_appearance`) and the selection
        ``before`` (N,) weighing :attr:`ClickOptions.carve_stickiness`. The click (its seeds
        ``clicked`` (S,)) changes only its own cell, the Gaussians nearer to its seeds than to
        any other click's, and those no click's view shows (:meth:`_unseen`), which no click
        speaks of and every cut decides: so a click on the wall behind a plant takes the wall
        off, and a later click on the plant brings back none of it. The ``first`` click that
        carves (:meth:`_firm`) decides the unseen Gaussians free of ``before`` (the first
        click's selection of the scene is the vote's, no choice of the user's) and the cells
        of all negative clicks so far (those before it spoke as with masks: a click on the
        fern's ceiling, held at one half, took 191 Gaussians; with the carving from the next
        click on, the ceiling goes). Of the unseen it takes only those that look like the
        negative seeds rather than like the rest of ``before`` (:meth:`_alike`): no view shows
        the others, and the graph alone gave them to the click. On DTU scan 24 joined to its
        surroundings, a click on the white table beside the house took 3 514 of the house's
        Gaussians, 2 502 of them its back, nearer along the graph to the table than to the
        click on its front (mIoU 0.959 -> 0.886; with the rule 0.947).

        Where ``within`` (N,) bool is given, a negative click carves apart a part the masks
        joined to an object that does not fill the scene (:meth:`_apart`; ``clicked``: all
        the negative seeds): the Gaussians nearer to a negative seed than to any positive
        one, what an earlier click left there of another colour too, and of those the ones
        ``within`` (N,) it (held no more firmly than the clicked part, and not out of its reach
        by colour: :meth:`_alike`), hidden or not (the table behind the tools on it).

        Where ``framed`` (the first click's view frames the object: :meth:`_reframed`), the
        object's colours are learned from the Gaussians selected ``before`` that lie at least
        :attr:`ClickOptions.split_full` nearer to a positive seed (a click beside the object
        does not teach them the ground's), and the unseen are no click's: the first click's
        cut decided them."""
        o = self.options
        nearer = self._nearer(positive, negative)
        unseen = self._unseen(clicks) if within is None and not framed else np.zeros(len(before), bool)
        stickiness = np.where(unseen & first, 0.0, o.carve_stickiness)
        cost = o.split_weight * nearer + stickiness * np.where(before, 1.0, -1.0)
        if o.appearance_rounds:
            firm = before & (nearer >= o.split_full) if framed else np.ones(len(cost), bool)
            cost += o.appearance_weight * self._appearance(cost, positive, firm, negative)
        cut = self._min_cut(cost, positive, negative)
        clicked = negative if first else clicked
        others = np.setdiff1d(np.union1d(positive, negative), clicked)
        cell = (self.graph.distances(clicked) < self.graph.distances(others)) | unseen
        if within is not None:
            cell &= within
        elif first:  # of what no view shows it takes only what looks like its part
            cell &= ~unseen | (self._alike(clicked, before) > 0)
        return before | (cut & cell) if clicks[-1].positive else before & (cut | ~cell)

    def _nearer(self, positive: np.ndarray, negative: np.ndarray) -> np.ndarray:
        """(N,) in [-1, 1]: how much nearer, along the graph, each Gaussian lies to a ``positive``
        (S,) seed than to a ``negative`` (S',) one, (d- - d+) / (d- + d+); 1 where no negative
        seed is reached, -1 where only a negative one is."""
        to_positive, to_negative = self.graph.distances(positive), self.graph.distances(negative)
        with np.errstate(invalid="ignore"):
            nearer = (to_negative - to_positive) / np.maximum(to_negative + to_positive, 1e-12)
        return np.where(np.isinf(to_negative), 1.0, np.where(np.isinf(to_positive), -1.0, nearer))

    def _frame(self, click: ClickEvidence, positive: np.ndarray, share: np.ndarray | None = None) -> np.ndarray | None:
        """The Gaussians that frame the object in the view of the first ``click``: those
        carrying :attr:`ClickOptions.seed_share` of its frame's weight
        (:attr:`ClickEvidence.frame`), less the ``positive`` (S,) seeds and those whose colour
        lies within :attr:`ClickOptions.apart_colour` (CIE76 in Lab) of a positive seed's (the
        object where it reaches the frame); None where the click has no view, where the views'
        vote (``share`` (N,), where given) holds under :attr:`ClickOptions.frame_held` of the
        frame's weight (masks that say where the object ends, though it fills most of every
        view), or where none is left (an object that fills its view)."""
        if click.frame is None or click.frame.sum() <= 0:
            return None
        if share is not None and click.frame[share > 0.5].sum() < self.options.frame_held * click.frame.sum():
            return None
        frame = np.setdiff1d(ClickEvidence(click.frame, False).seeds(self.options.seed_share), positive)
        frame = frame[self._apart_in_colour(self.colours.lab[frame], positive)]
        return frame if len(frame) else None

    def _apart_in_colour(self, lab: np.ndarray, positive: np.ndarray) -> np.ndarray:
        """(K,) bool: whether each of the colours ``lab`` (K, 3) (CIE Lab) lies at least
        :attr:`ClickOptions.apart_colour` (CIE76) from every ``positive`` (S,) seed's colour."""
        return cKDTree(self.colours.lab[positive]).query(lab)[0] >= self.options.apart_colour

    def _unlike(self, selected: np.ndarray, off: np.ndarray) -> np.ndarray:
        """(N,) bool: the Gaussians whose colour is at least :attr:`ClickOptions.far_colour`
        log-units likelier under the colours of the ``off`` (S,) Gaussians (the frame, the
        negative seeds) than under those of the ``selected`` (N,) bool ones: colours the object
        does not have and the rest does. A later positive click whose pixel shows the backdrop
        through a gap in the statue pins none of the backdrop."""
        return self._against(selected, off) <= -self.options.far_colour

    def _against(self, selected: np.ndarray, off: np.ndarray) -> np.ndarray:
        """(N,) each Gaussian's colour log-likelihood ratio (:meth:`ColourModel.ratio`) under the
        colours of the ``selected`` (N,) bool Gaussians against those of the ``off`` (S,) ones
        not selected (the frame, the negative seeds)."""
        return self.colours.ratio(selected, self._mask(off) & ~selected)

    def _reframed(
        self,
        clicks: Sequence[ClickEvidence],
        seeds: list[tuple[np.ndarray, bool]],
        frame: np.ndarray,
        before: np.ndarray,
    ) -> np.ndarray:
        """(N,) bool: the selection after the last of ``clicks`` where the first click's view
        frames the object (:meth:`_framed`), from the selection ``before`` (N,). A click on the
        selection's edge (:meth:`_on_edge`) moves the edge by its seeds alone: a positive one
        adds those beside the selection (:meth:`_beside`) whose colour is likelier under the
        selection's colours than under the rest's, a negative one takes out those likelier
        under the rest's. Where a positive one adds none of them, it lands on a part the first
        cut missed a few spacings beyond the edge (:meth:`_missed`: the gold crown of a bronze
        head whose dark face the first click selected): it carves as below from those seeds,
        and adds of the cut only what has their colours and the graph joins to them. A
        positive click whose seeds all lie farther from the selection than it is wide
        (:meth:`_far_off`) changes nothing. Elsewhere the clicks carve (:meth:`_carved`, the
        object's colours learned from the selection), each changing its own cell: the first click's seeds
        (``seeds``: each click's, and whether it is positive) and those of the later ones on
        the side the selection put them on are pinned, the last click's too, less, for a
        positive one, those from elsewhere beside the selection's rim (:meth:`_beside`) and
        those of colours the object lacks and the frame has (:meth:`_unlike`); the ``frame``
        (S,) holds the rest out, less the Gaussians of a pinned seed's colour and
        those nearer along the graph to a positive click's new seeds than the first click's
        seeds are (the object reaches the frame where a click says so).

        A positive click of a colour the ``frame`` holds (one of its Gaussians within
        :attr:`ClickOptions.apart_colour` of a seed's) says that the object reaches the
        view's border, where the first cut took it for the rest (DTU's house fills its views
        and reaches three sides of the frame): it cuts the object again from all the pinned
        seeds and the frame less what is of their colours (:meth:`_framed`), and adds what
        that cut joins to them, not its cell alone. A click whose colour the frame lacks (a
        part missed beside an object inside the frame) carves its cell: cut again from a
        seed by the object's edge, the ground beside it comes too (``benchmarks.click_quality``'s
        orbit, seed 1, object 1 with the clicks alone: 0.58 -> 0.37, where its cell gives 0.97)."""
        o = self.options
        last, (own, _) = clicks[-1], seeds[-1]
        earlier = seeds[1:-1]
        positive = np.concatenate([seeds[0][0], *(k[before[k]] for k, on in earlier if on)])
        negative = np.concatenate([np.zeros(0, np.int64), *(k[~before[k]] for k, on in earlier if not on)])
        edge, missed = last.seeds(o.seed_share, o.seed_local), None
        if self._on_edge(last, edge, before):
            moved = self._edge_moved(last, edge, before)
            if not last.positive or (moved & ~before).any():
                return moved
            missed = self._missed(edge, before, np.union1d(negative, frame))
            if not len(missed):
                return before
        reaches_frame = last.positive and not self._apart_in_colour(self.colours.lab[frame], own).all()
        if last.positive:
            if missed is None:
                held_off = np.flatnonzero(~before & self._unlike(before, np.union1d(negative, frame)))
                own = np.setdiff1d(self._beside(last, own, before), held_off)
            else:
                own = missed
            if before[own].all() or self._far_off(before, own):
                return before
            positive = np.union1d(positive, own)
            to_own = self.graph.distances(np.setdiff1d(own, np.flatnonzero(before)))
            frame = frame[to_own[frame] >= to_own[seeds[0][0]].min()]  # the object reaches the frame there
        else:
            negative = np.union1d(negative, own)
        positive = np.setdiff1d(positive, negative)
        reframed = self._frame(clicks[0], positive)
        frame = frame if reframed is None else np.intersect1d(frame, reframed)
        off = np.setdiff1d(np.union1d(negative, frame), positive)
        if reaches_frame:
            grown = before | self._framed(positive, off)
        else:
            grown = self._carved(clicks, own, positive, off, before, False, framed=True)
        if missed is None:
            return grown
        added = grown & ~before & (self._alike(missed, ~before) >= 1)  # of the missed seeds' colours
        return before | self.graph.joined(added, self._mask(missed))

    def _missed(self, seeds: np.ndarray, before: np.ndarray, off: np.ndarray) -> np.ndarray:
        """The unselected ``seeds`` (S,) of a positive click on the edge of a framed selection
        ``before`` (N,) that lie on a part the first cut missed: within
        :attr:`ClickOptions.missed_reach` spacings of a selected Gaussian, and of colours likelier
        under the selection's colours than under those of the ``off`` (S',) Gaussians (the frame
        and the negative seeds, which bound the object). A bronze head's gold crown lies 4-6
        spacings beyond the dark face the first cut selected, and its colours are nearer the
        face's than the floor's at the frame; the ground that a click beside a thin part lands
        on has the frame's colours."""
        missed = seeds[~before[seeds]]
        if not len(missed):
            return missed
        near = self._gap(before, missed) <= self.options.missed_reach * self.graph.spacing
        return missed[near & (self._against(before, off)[missed] > 0)]

    def _in_blur(self, click: ClickEvidence, seeds: np.ndarray, before: np.ndarray) -> bool:
        """Whether a negative ``click`` lands on what the selection ``before`` (N,) draws in its
        view within :attr:`ClickOptions.rim_spread` times the footprint of its ``seeds`` (S,)
        (their standard deviation in the view, :attr:`ClickEvidence.spread`, weighted by the
        click's weights) of the edge of what it draws (:attr:`ClickEvidence.inside`): a pixel the selection's
        rim draws as a blur beyond the object's edge (a model fitted no sharper than its
        photos), whose Gaussians are the object's own; taken out, they would cut the object's
        rim in this view and its side in the others. A part the masks joined to the object
        lies deeper inside what the selection draws than its Gaussians' blur."""
        if click.positive or click.inside is None or click.spread is None:
            return False
        weights = click.weights[seeds]
        blur = float(weights @ click.spread[seeds]) / max(float(weights.sum()), 1e-12)
        return 0 < click.inside(before) < self.options.rim_spread * blur

    def _on_edge(self, click: ClickEvidence, seeds: np.ndarray, before: np.ndarray) -> bool:
        """Whether ``click`` lands on the edge of the selection ``before`` (N,): its ``seeds``
        (S,) selected and those not each hold at least :attr:`ClickOptions.seen_share` of
        their weight (a pixel the selection's blurred rim and what lies beside it draw)."""
        held = self._held_share(click, seeds, before)
        return bool(self.options.seen_share <= held <= 1 - self.options.seen_share)

    @staticmethod
    def _held_share(click: ClickEvidence, seeds: np.ndarray, before: np.ndarray) -> float:
        """The share of ``click``'s weight on its ``seeds`` (S,) that the selection ``before``
        (N,) holds."""
        weights = click.weights[seeds]
        return float(weights[before[seeds]].sum()) / max(float(weights.sum()), 1e-12)

    def _edge_moved(self, click: ClickEvidence, seeds: np.ndarray, before: np.ndarray) -> np.ndarray:
        """(N,) bool: the selection ``before`` (N,) with its edge moved by a ``click`` on it
        (:meth:`_on_edge`) and its ``seeds`` (S,) alone: a positive click adds those beside the
        selection (:meth:`_beside`) whose colour is likelier under the selection's colours
        than under the rest's, a negative one takes out those likelier under the rest's. The
        pixel is drawn by the selection's blurred rim and what lies beside it at once: the
        graph beyond the seeds says nothing of where the object ends."""
        ratio = self.colours.ratio(before, ~before)
        if not click.positive:
            return before & ~self._mask(seeds[ratio[seeds] < 0])
        seeds = self._beside(click, seeds, before)
        return before | self._mask(seeds[ratio[seeds] > 0])

    def _beside(self, click: ClickEvidence, seeds: np.ndarray, before: np.ndarray) -> np.ndarray:
        """The ``seeds`` (S,) a later positive ``click`` pins where its view's frame bounds the
        object (:meth:`_reframed`): all, or where the selection ``before`` (N,) holds
        :attr:`ClickOptions.seen_share` of the weight of the click's seeds or more (the click
        lands on it in part), the selected ones and those within
        :attr:`ClickOptions.part_reach` spacings of a selected Gaussian: what shows through a
        gap in the selection, or lies over its rim, from elsewhere stays out (a click on a
        statue whose pixel shows the building 150 units behind it). Where the selected seeds
        hold less (a sliver of the pixel), the click lands on a part the first cuts missed
        beside the selection: those within :attr:`ClickOptions.missed_reach` spacings. With
        the clicks alone on DTU scan 24, a click on a roof the cuts had left out, its seeds
        4-22 spacings beyond the selection and one selected seed with 4% of their weight,
        added nothing (mIoU 0.84); it now adds the roof (3 935 of the 3 975 Gaussians it adds
        are the house's: 0.91)."""
        o = self.options
        if not before[seeds].any():
            return seeds
        gap = self._gap(before, seeds)
        if self._held_share(click, click.seeds(o.seed_share, o.seed_local), before) < o.seen_share:
            return seeds[gap <= o.missed_reach * self.graph.spacing]
        return seeds[before[seeds] | (gap <= o.part_reach * self.graph.spacing)]

    def _framed(self, positive: np.ndarray, frame: np.ndarray) -> np.ndarray:
        """(N,) bool: the object cut from the frame where the views' vote holds the scene and
        the first click's view frames the object (the first click's selection, and that of a
        later positive one of a colour the frame holds: :meth:`_reframed`): each Gaussian is
        the object's in proportion to how much nearer, along the graph, it lies to a
        ``positive`` (S,) seed than to one of the ``frame`` (S',) (:meth:`_frame`), times
        :attr:`ClickOptions.split_weight`, with colour models learned from the cut
        (:meth:`_appearance`), the object's from the Gaussians at least
        :attr:`ClickOptions.split_full` nearer to it (the cut's reach halfway to the frame
        does not teach them the ground's colours); what the graph joins to the seeds. As
        GrabCut cuts the object from the frame of a box, without masks."""
        o = self.options
        nearer = self._nearer(positive, frame)
        cost = o.split_weight * nearer
        if o.appearance_rounds:
            cost += o.appearance_weight * self._appearance(cost, positive, nearer >= o.split_full, frame)
        return self.graph.joined(self._min_cut(cost, positive, frame), self._mask(positive))

    def _unseen(self, clicks: Sequence[ClickEvidence]) -> np.ndarray:
        """(N,) bool: the Gaussians that no click's view shows :attr:`ClickOptions.shown_share`
        of (:attr:`ClickEvidence.shown`): in an orbit, the far side of the scene from the
        clicked view."""
        return np.max([self._shown_by(click) for click in clicks], axis=0) < 1.0

    def _alike(self, seeds: np.ndarray, others: np.ndarray) -> np.ndarray:
        """(N,) in [0, 1]: how far each Gaussian looks like a click's ``seeds`` (S,) rather
        than like the ``others`` (N,) bool: fully where it is at least as likely under the
        seeds' colours as under the others', none where it is
        :attr:`ClickOptions.against_colour` log-units likelier under the others', linearly
        between. For a negative click the others are the selection: a floater beside a head
        goes, the head's own side next to it, of the head's colours, stays; where the clicked
        part looks like the object, the graph alone decides."""
        mask = self._mask(seeds)
        return self._likeness(self.colours.ratio(mask, others & ~mask))

    def _likeness(self, ratio: np.ndarray) -> np.ndarray:
        """(N,) in [0, 1] of a colour log-likelihood ``ratio`` (N,) (:meth:`ColourModel.ratio`):
        1 from 0 up, 0 from -:attr:`ClickOptions.against_colour` down, linearly between."""
        return np.clip(1 + ratio / self.options.against_colour, 0, 1)

    def _grown(
        self,
        click: ClickEvidence,
        seeds: np.ndarray,
        negative: np.ndarray,
        share: np.ndarray,
        weight: np.ndarray,
        hazy: np.ndarray,
        before: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray]:
        """(N,) in [0, 1]: how far each Gaussian lies in the part a later positive ``click``
        adds, and the indices of its ``seeds`` (S,) the click pins: those of the selection and
        those the part grows from. The part is a negative click's side mirrored: over the
        graph, nearer to the seeds that lie beside the selection ``before`` (N,) (within
        :attr:`ClickOptions.part_reach` spacings of a selected Gaussian; the click lands
        beside it where these hold most of its unselected seeds' weight) than to the Gaussians
        the views hold off the object (unselected, seen, with a ``share`` (N,) of their
        ``weight`` (N,) in the object's regions under :attr:`ClickOptions.off_share`, or under
        one half where ``hazy`` (N,): :meth:`_hazy`) and the ``negative`` (S',) seeds; shown by
        the click's view and alike in colour to the seeds rather than to the rest of the
        unselected Gaussians. A highlight on a bronze head that the masks hold as a region of
        its own, and the views therefore vote off the head, comes in whole with a click on it.

        Where most of the seeds do not lie beside the selection, the click lands deep inside
        a part the views hold off the object with its surroundings (masks that gave a box's
        lid to the bench under it: the vote cannot tell the two apart). The part is then every Gaussian
        nearer along the graph to the seeds than to those of the Gaussians held off whose
        colour the object (the selection and the seeds) does not have
        (:attr:`ClickOptions.far_colour`), alike means alike to the object, and what the
        click's view hides of the part comes too where it looks like the part's front
        (:meth:`_like_its_front`): bounded by colour, its far side is as much the part as its
        front. An object is one piece: the part holds only what the graph joins
        to the selection, and the click pins only its seeds there. A click on a ball's rim where
        the edge of a box of its colour in front of it draws the pixel lands on the box's
        Gaussians, 184 spacings from the ball: the box came whole (mIoU 0.974 -> 0.451 on
        ``benchmarks.click_quality``'s orbit, seed 1)."""
        o = self.options
        kept = seeds[before[seeds]]  # what the click lands on of the selection
        seeds = seeds[~before[seeds]]
        if not before.any() or not len(seeds):
            return np.zeros(len(self.labels)), kept
        beside = self._gap(before, seeds)
        off = ~before & (weight > 0) & ((share < o.off_share) | hazy & (share < 0.5))
        reached = beside <= o.part_reach * self.graph.spacing
        weights = click.weights[seeds]
        near = bool(weights[reached].sum() >= 0.5 * weights.sum()) if weights.sum() > 0 else bool(reached.any())
        if near:
            seeds = seeds[reached]
            alike = self._alike(seeds, ~before)
        else:
            obj = before | self._mask(seeds)
            ratio = self.colours.ratio(obj, ~obj)
            off &= ratio <= -o.far_colour
            alike = self._likeness(ratio)
        bound = np.setdiff1d(np.union1d(np.flatnonzero(off), negative), seeds)
        side = self.graph.split(seeds, bound)
        if near:
            return np.clip(side / o.split_full, 0, 1) * self._shown_by(click) * alike, np.union1d(kept, seeds)
        part = self.graph.joined(side > 0, before)  # deep inside, the part's hidden side too
        return part * alike * self._like_its_front(click, part, before), np.union1d(kept, seeds[part[seeds]])

    def _like_its_front(self, click: ClickEvidence, part: np.ndarray, before: np.ndarray) -> np.ndarray:
        """(N,) in [0, 1]: for a ``part`` (N,) bool that a later positive ``click`` adds from
        deep inside it, 1 where the click's view shows a Gaussian fully; elsewhere how far it
        looks like what the view shows of the part rather than like the rest of the unselected
        Gaussians (``before`` (N,) the selection; :meth:`_alike`). What the view hides of
        a part comes where it is of the part's colours, not merely of the object's: a click
        on the grey plate under a model house grew, through the plate, into the black
        backdrop behind it, which the house's colours hold and the plate's do not (DTU scan
        24: 189 of the 468 Gaussians the click added, mIoU 0.959 -> 0.898)."""
        shown = self._shown_by(click) >= 1
        front = part & shown
        if not front.any():
            return np.ones(len(self.labels))
        return np.where(shown, 1.0, self._alike(np.flatnonzero(front), ~before))

    def _held_off(self, click: ClickEvidence, share: np.ndarray) -> bool:
        """Whether the views' vote holds what ``click`` lands on off the object: its seeds'
        ``share`` (N,) (:meth:`_seeds_share`) under :attr:`ClickOptions.off_share`."""
        held = self._seeds_share(click, share)
        return held is not None and held < self.options.off_share

    def _firm(self, clicks: Sequence[ClickEvidence]) -> list[int]:
        """The indices in ``clicks`` of the negative clicks whose seeds the first click's vote
        holds firmly (their share, :meth:`_seeds_share`, at least
        :attr:`ClickOptions.carve_share`; the first click's, so that the carving, once begun,
        starts at the same click whatever the later ones add). Where the vote holds the scene
        the clicks carve from the first of them (:meth:`_carved`). Such a click tells the
        object from a part the masks joined to it (the wall behind a plant), which only the
        clicks can cut.
        One on what the vote holds loosely tells the object from its spill: on DTU's house,
        which fills most of every view, a click in the view's corner lands on large Gaussians
        of the house drawn over the background, held at 0.52; carving from there took the back
        of the house, 2 508 Gaussians the clicked view does not show (mIoU 0.959 -> 0.889),
        the cut with the vote took 6 Gaussians of the spill (0.959 -> 0.959)."""
        share, _, _ = self.views_vote(clicks[:1], None)
        held = [None if click.positive else self._seeds_share(click, share) for click in clicks]
        return [k for k, h in enumerate(held) if h is not None and h >= self.options.carve_share]

    def _apart(
        self, clicks: Sequence[ClickEvidence], firm: list[int], seeds: list[tuple[np.ndarray, bool]]
    ) -> list[int]:
        """The indices in ``clicks`` of the negative clicks that carve their part apart from
        the object where the views' vote does not hold the scene (:meth:`_carved`, within the
        negative clicks' side of the graph): of the ``firm`` ones (:meth:`_firm`: the masks
        joined the clicked part to the object, and the vote cannot tell the two apart), those
        whose colour (their mean in CIE Lab, by the click's weight) lies at least
        :attr:`ClickOptions.apart_colour` from that of every positive seed of the clicks before
        it (``seeds``: each click's, and whether it is positive), so that a later click never
        undoes the carving (a positive click at an object's foot whose pixel the table carved
        off draws does not make the table the object's colour). A click
        on the edge of a bronze head whose colour the head has is a negative click as with
        masks: carved, the graph's split took 215-495 of the head's Gaussians a click (the
        head's curve 0.931 -> 0.878 over ten clicks), where
        clicks on the ground the masks joined to a statue take the ground, what their view
        hides of it too. Over the three captures' forced clicks (``benchmarks.real_scenes``)
        the colour lay 0.1-5.5 from a positive seed's where carving took the object's
        Gaussians, 25-36 where it took the part joined to it; with the later rules the ranges
        meet (the head's rim with its own masks 13.0-15.9, carved at a loss; the statue's
        joined ground 12.6-13.6, carved at a gain: docs/segmentation.md)."""
        o = self.options
        apart = []
        for k in firm:
            positive = np.concatenate([np.zeros(0, np.int64), *(s for s, on in seeds[:k] if on)])
            own = clicks[k].seeds(o.seed_share, o.seed_local)
            colour = np.average(self.colours.lab[own], axis=0, weights=clicks[k].weights[own])
            if len(positive) and self._apart_in_colour(colour[None], positive)[0]:
                apart.append(k)
        return apart

    def _seeds_share(self, click: ClickEvidence, share: np.ndarray) -> float | None:
        """The views' ``share`` (N,) of ``click``'s seeds, weighed by the click's weight
        (None where they weigh nothing)."""
        o = self.options
        seeds = click.seeds(o.seed_share, o.seed_local)
        weights = click.weights[seeds]
        return float(np.average(share[seeds], weights=weights)) if weights.sum() > 0 else None

    def _hazy(self, weight: np.ndarray) -> np.ndarray:
        """(N,) bool: the Gaussians whose ``weight`` (N,) in the views is at least
        :attr:`ClickOptions.off_weight` times the median seen Gaussian's, or whose longest axis
        is at least :attr:`ClickOptions.large_size` times the median Gaussian's: large hazy
        ones, drawn over much of every view. A later positive click does not pin such seeds
        (nor grow from them): what it lands on of one is a sliver of what it draws. On the
        forced clicks of the statue, DTU and the head (``benchmarks.real_scenes``, 1 000 and
        2 000 steps) the unselected seeds of later positive clicks were off the object (by the
        people's masks) 63 times of 69 where their weight was that large, 41 of 253 elsewhere;
        on the demo's models, with the clicks alternating between two views, 70 of 72 where
        only their size was (a click on a statue's rim whose pixel shows what stands behind
        it, drawn by Gaussians 16-46 times the median size, brought a streak of it: mIoU
        0.937 -> 0.771)."""
        seen = weight > 0
        heavy = weight >= self.options.off_weight * float(np.median(weight[seen])) if seen.any() else seen
        return heavy | self.large

    def _pinned(self, click: ClickEvidence, seeds: np.ndarray, hazy: np.ndarray) -> np.ndarray:
        """The seeds a later positive ``click`` pins, of its ``seeds`` (S,): those not ``hazy``
        (N,) (:meth:`_hazy`), or where all are, those of them under
        :attr:`ClickOptions.large_size` times the median Gaussian's size that the click lands
        on more than a sliver of (:attr:`ClickEvidence.local` at least
        :attr:`ClickOptions.sliver`). An object near the camera is drawn by Gaussians each
        heavy in the views: on the synthetic forward path (``benchmarks.edit_quality``, seed 1)
        all five seeds of a click on such an object were heavy, and on it, and the click added
        nothing. A click on a bronze head's cheek whose pixel four heavy Gaussians of the floor
        beside it draw, each with 0.5-3% of its weight in the view there, brought them and the
        floor they draw (mIoU 0.925 -> 0.876)."""
        kept = seeds[~hazy[seeds]]
        if len(kept):
            return kept
        kept = seeds[~self.large[seeds]]
        return kept if click.local is None else kept[click.local[kept] >= self.options.sliver]

    def _shown_by(self, click: ClickEvidence) -> np.ndarray:
        """(N,) in [0, 1]: how much of each Gaussian the ``click``'s view shows, in shares of
        :attr:`ClickOptions.shown_share` (all of each Gaussian for a click without a view)."""
        shown = np.ones(len(self.labels)) if click.shown is None else click.shown
        return np.clip(shown / self.options.shown_share, 0, 1)

    def _in_sight(self, clicks: Sequence[ClickEvidence]) -> np.ndarray:
        """(N,) in [0, 1]: how far each Gaussian lies within a negative click's reach, by how
        much of it the clicked view shows: fully from :attr:`ClickOptions.shown_share` on,
        linearly below. A negative click speaks of what its view shows: the back of a head
        that the view hides behind its face is beyond it, however near along the graph to the
        clicked rim."""
        reach = np.zeros(len(self.labels))
        for click in clicks:
            if not click.positive:
                reach = np.maximum(reach, self._shown_by(click))
        return reach

    def _yielding(
        self,
        clicks: Sequence[ClickEvidence],
        negative: np.ndarray,
        objects: np.ndarray,
        share: np.ndarray,
        seen: np.ndarray,
    ) -> np.ndarray:
        """(N,) in [0, 1]: how far each Gaussian on a negative click's side gives way to it.
        In each view where a negative click is seen, the region under it (the background too)
        unless it is one of the object's ``objects`` (R,) regions; a Gaussian's hold on the
        object is its ``share`` (N,) of weight in the object's regions less its share in the
        click's. A Gaussian whose hold exceeds the mean hold of the click's ``negative`` (S,)
        seeds by twice :attr:`ClickOptions.against_margin` keeps its evidence, one within a
        margin of it gives way fully, linearly between: the object's own parts beside a spill
        or floater, which the views give to the object more firmly than the spill, stay. Where
        the views hold the clicked part as firmly as the rest (masks that join it to the
        object), the graph alone decides."""
        o = self.options
        under = np.zeros(len(self.vote.label), bool)
        for click in clicks:
            if not click.positive:
                under |= self.vote.clicked_regions(click, o.seen_share, any_label=True)
        against, told = self.vote.shares(under & ~objects)
        hold = share - np.where(told > 0, against, 0.0)
        return np.where(seen, np.clip(2 - (hold - hold[negative].mean()) / o.against_margin, 0, 1), 1.0)
