"""Selections made by clicks (``gsseg edit --click ... --exclude-click ...``, the viewer): the
views' mask regions under a click, the labels where they agree, a cut over the Gaussians."""

from __future__ import annotations

import json
import shutil
import subprocess
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp
import torch
from helpers import script
from scipy.spatial import cKDTree

from dataset_tools.cameras import CameraPose, PinholeCamera
from dataset_tools.image_files import encode_png
from dataset_tools.infra.atomic import write_bytes_atomic
from dataset_tools.infra.errors import InputError
from dataset_tools.scene import load_scene
from gsseg.model.gaussians import gaussians_from_points
from gsseg.model.ply import read_ply
from gsseg.render.contributions import RegionWeights
from gsseg.render.projection import EPS_2D
from gsseg.run.loaded import load_run
from gsseg.segment.clicks import ClickEvidence, ClickOptions, ClickSelector, ColourModel, RegionVote, SceneHeld
from gsseg.segment.prompts import click_evidence, framed_object, object_click
from gsseg.segment.segment_run import segment_run
from gsseg.segment.served import complete_selection

# --- the rule on a drawn model: two blobs, what the views and the labels say of them ----------


def _two_blobs():
    """200 red Gaussians about x = 0 (A) and 200 blue ones about x = 3 (B)."""
    rng = np.random.default_rng(0)
    xyz = np.concatenate([rng.normal(0, 0.3, (200, 3)), rng.normal(0, 0.3, (200, 3)) + [3.0, 0, 0]])
    rgb = np.concatenate([np.tile([200, 30, 30], (200, 1)), np.tile([30, 30, 200], (200, 1))]).astype(np.uint8)
    return gaussians_from_points(xyz, rgb, initial_opacity=0.9), np.arange(200), np.arange(200, 400)


def _regions(n: int, groups: list[np.ndarray], views: int = 6) -> RegionWeights:
    """Each of ``views`` views shows every Gaussian with weight 1, in one region per group (the
    Gaussians of a group under one mask label, 1, 2, ...) and the rest under label 0."""
    rows, view, label = [], [], []
    for v in range(views):
        rest = np.ones(n, bool)
        for k, group in enumerate(groups):
            row = np.zeros(n, np.float32)
            row[group] = 1
            rest[group] = False
            rows.append(row), view.append(v), label.append(k + 1)
        rows.append(rest.astype(np.float32)), view.append(v), label.append(0)
    return RegionWeights(
        sp.csr_matrix(np.stack(rows)), np.array(view), np.array(label, np.uint8), np.zeros(len(view), np.uint8), ("m",)
    )


def _click(n: int, on: np.ndarray, positive: bool = True, shown: np.ndarray | None = None) -> ClickEvidence:
    weights = np.zeros(n)
    weights[on[:5]] = 1.0
    return ClickEvidence(weights, positive, shown)


def test_a_click_selects_what_the_views_hold_apart_although_the_labels_join_it():
    g, a, b = _two_blobs()
    n = len(g)
    joined = np.full(n, 7, np.uint8)  # the 3D labels joined A and B
    selector = ClickSelector(g, joined, _regions(n, [a, b]))  # every view holds them apart
    selected = selector.select([_click(n, a)])
    assert selected[a].all() and not selected[b].any()
    with pytest.raises(InputError, match="click on it first"):
        selector.select([_click(n, b, positive=False)])


def test_a_negative_click_takes_out_a_part_the_views_and_labels_joined():
    g, a, b = _two_blobs()
    n = len(g)
    selector = ClickSelector(g, np.full(n, 7, np.uint8), _regions(n, [np.concatenate([a, b])]))
    both = selector.select([_click(n, a)])
    assert both.all()
    alone = selector.select([_click(n, a), _click(n, b, positive=False)])
    assert alone[a].all() and not alone[b].any()


def test_a_click_knows_how_much_of_each_gaussian_its_view_shows():
    """Known answers of ``shown``: a Gaussian alone in view gives its whole footprint
    o 2 pi sqrt(det Sigma2D) (1 up to the cut at alpha 1/255 and the pixel grid), one behind a
    nearly opaque one almost nothing, one behind the camera nothing."""
    g = gaussians_from_points(
        np.array([[0.0, 0.0, 5.0], [0.0, 0.0, 8.0], [3.0, -3.0, 8.0], [0.0, 0.0, -3.0]]),
        np.full((4, 3), 128, np.uint8),
        initial_opacity=0.5,
    )
    g.log_scales = torch.log(torch.tensor([1.0, 0.1, 0.2, 0.2]))[:, None].repeat(1, 3)
    g.opacity_logits = torch.logit(torch.tensor([0.995, 0.5, 0.5, 0.5]))
    camera = PinholeCamera(128, 128, 100.0, 100.0, 64.0, 64.0)
    seen = click_evidence(g, camera, np.eye(4)[:3], 64.0, 64.0)
    assert seen.shown[0] == pytest.approx(1.0, abs=0.05) and seen.shown[2] == pytest.approx(1.0, abs=0.05)
    assert seen.shown[1] < 0.02 and seen.shown[3] == 0.0
    assert seen.positive and seen.weights[0] > 0.9 * seen.weights.sum()


def _on_a_backdrop(xyz: np.ndarray, rgb: np.ndarray):
    """Gaussians at ``xyz`` (N, 3) of colours ``rgb`` (N, 3), then 600 grey ones about x = -6
    that no click touches: the rest of the scene, which the masks hold apart from the first N
    (the views' vote then does not hold the scene, :meth:`RegionVote.holds_the_scene`)."""
    backdrop = np.random.default_rng(5).normal(0, 0.3, (600, 3)) + [-6.0, 0, 0]
    rgb = np.concatenate([rgb, np.full((600, 3), 128)]).astype(np.uint8)
    return gaussians_from_points(np.concatenate([xyz, backdrop]), rgb, initial_opacity=0.9)


def _two_blobs_on_a_backdrop():
    """:func:`_two_blobs` on :func:`_on_a_backdrop`."""
    g, a, b = _two_blobs()
    rgb = np.concatenate([np.tile([200, 30, 30], (200, 1)), np.tile([30, 30, 200], (200, 1))])
    return _on_a_backdrop(g.means.numpy(), rgb), a, b


def test_a_negative_click_reaches_only_what_its_view_shows():
    """B has A's colour, and the clicked view shows B's near half alone (its far half hidden
    behind it, as a face hides the back of a head): a negative click on B takes that half; the
    hidden half keeps what the views and labels say of it, and the same click seeing all of B
    takes all of it. (Of another colour than A, B would be carved apart whole:
    :func:`test_a_negative_click_carves_apart_a_surface_the_masks_joined_to_the_object`.)"""
    g, a, b = _two_blobs()
    g = _on_a_backdrop(g.means.numpy(), np.tile([200, 30, 30], (400, 1)))
    n = len(g)
    selector = ClickSelector(g, np.full(n, 7, np.uint8), _regions(n, [np.concatenate([a, b])]))
    far = g.means[:, 0].numpy() > 3.0
    shown = np.where(far, 0.0, 1.0)
    near_b, far_b = b[~far[b]], b[far[b]]
    against = _click(n, near_b, positive=False, shown=shown)
    part = selector.select([_click(n, a), against])
    assert part[a].all() and not part[near_b].any() and part[far_b].all()
    whole = selector.select([_click(n, a), replace(against, shown=np.ones(n))])
    assert whole[a].all() and not whole[b].any()


def test_clicks_carve_the_object_alone_where_the_masks_hold_the_whole_scene():
    """Every view holds A, B and all else as one region (weight-free masks of a plant in front
    of a wall): the views' vote holds the scene, and the clicks carve the object by the graph.
    A negative click on B takes all of B, the half its view hides too (nothing else speaks of
    it), and a later positive click on A brings none of B back; where the masks hold the
    blobs apart from a backdrop, the vote does not hold the scene."""
    g, a, b = _two_blobs()
    n = len(g)
    selector = ClickSelector(g, np.full(n, 7, np.uint8), _regions(n, [np.arange(n)]))
    first = _click(n, a)
    share, _, _ = selector.views_vote([first], None)
    assert selector.vote.holds_the_scene(share, first, selector.options.seen_share)
    assert selector.select([first]).all()
    hidden = np.where(g.means[:, 0].numpy() > 3.0, 0.0, 1.0)
    clicks = [first, _click(n, b[g.means[b, 0].numpy() <= 3.0], positive=False, shown=hidden)]
    carved = selector.select(clicks)
    assert carved[a].all() and not carved[b].any()
    again = selector.cut([*clicks, _click(n, a[5:])], carved)
    assert np.array_equal(again, carved)
    rng, before = np.random.default_rng(3), again
    for _ in range(8):  # the carving keeps each click's way too
        click = _click(n, rng.choice(n, 5, replace=False), positive=bool(rng.random() < 0.5))
        clicks.append(click)
        after = selector.cut(clicks, before)
        assert (after >= before).all() if click.positive else (after <= before).all()
        before = after
    g, a, b = _two_blobs_on_a_backdrop()
    kept = ClickSelector(g, np.full(len(g), 7, np.uint8), _regions(len(g), [np.concatenate([a, b])]))
    share, _, _ = kept.views_vote([_click(len(g), a)], None)
    assert not kept.vote.holds_the_scene(share, _click(len(g), a), kept.options.seen_share)


def _bar_in_a_frame():
    """A bar of 900 Gaussians along x from -3 to 3, one region in every view (the views' vote
    holds the scene): A (red, |x| <= 1) in the middle, green from 1 to 2, blue beyond; and the
    weights of a view whose frame shows the bar's ends (|x| > 2.5): (Gaussians, x, A, frame)."""
    rng = np.random.default_rng(0)
    x = rng.uniform(-3, 3, 900)
    xyz = np.stack([x, rng.normal(0, 0.2, 900), rng.normal(0, 0.2, 900)], 1)
    rgb = np.where(
        (np.abs(x) <= 1)[:, None], [200, 30, 30], np.where(((x > 1) & (x <= 2))[:, None], [30, 200, 30], [30, 30, 200])
    )
    g = gaussians_from_points(xyz, rgb.astype(np.uint8), initial_opacity=0.9)
    return g, x, np.flatnonzero(np.abs(x) <= 1), np.where(np.abs(x) > 2.5, 1.0, 0.0)


def test_a_first_click_where_the_masks_hold_the_scene_is_cut_from_its_views_frame():
    """The masks hold the bar as one region, so neither the views nor the labels say where A
    ends. A click on A whose view's frame shows the bar's ends selects A alone, as GrabCut
    cuts an object from the frame of its box; a click without a view (a 3D point) selects
    the scene, and so does one whose frame has A's colours (A fills its view), or whose frame
    the masks hold apart from A (they say where it ends)."""
    g, x, a, frame = _bar_in_a_frame()
    selector = ClickSelector(g, np.full(900, 7, np.uint8), _regions(900, [np.arange(900)]))
    centre = a[np.argsort(np.abs(x[a]))]
    first = replace(_click(900, centre), frame=frame)
    share, _, _ = selector.views_vote([first], None)
    assert selector.vote.holds_the_scene(share, first, selector.options.seen_share)
    np.testing.assert_array_equal(selector.select([first]), np.abs(x) <= 1)
    assert selector.select([_click(900, centre)]).all()
    assert selector.select([replace(first, frame=np.where(np.abs(x) < 0.5, 1.0, 0.0))]).all()
    wide = np.flatnonzero(np.abs(x) <= 2.2)  # the masks' region: most of every view, not its frame
    told = ClickSelector(g, np.full(900, 7, np.uint8), _regions(900, [wide]))
    share, _, _ = told.views_vote([first], None)
    assert told.vote.holds_the_scene(share, first, told.options.seen_share)
    assert told.select([first])[wide].all()


def test_a_click_on_the_edge_of_a_framed_selection_moves_it_by_its_seeds_alone():
    """A is selected (:func:`test_a_first_click_where_the_masks_hold_the_scene_is_cut_from_its_views_frame`);
    clicks whose pixels A and the green beside it share (a blurred rim) change the selection by
    their own seeds alone: a positive one adds none of the green (colours A lacks), a negative
    one takes none of A's red. A positive click on the green, away from A, adds the green,
    and one on a blue end, of the frame's colours which A lacks, adds nothing."""
    g, x, a, frame = _bar_in_a_frame()
    selector = ClickSelector(g, np.full(900, 7, np.uint8), _regions(900, [np.arange(900)]))
    first = replace(_click(900, a[np.argsort(np.abs(x[a]))]), frame=frame)
    selected = selector.select([first])
    rim = np.concatenate([a[np.argsort(-x[a])][:3], np.flatnonzero(x > 1)[np.argsort(x[x > 1])][:3]])
    for positive in (True, False):
        edge = ClickEvidence(np.isin(np.arange(900), rim).astype(float), positive)
        np.testing.assert_array_equal(selector.cut([first, edge], selected), selected)
    green = np.flatnonzero((x > 1) & (x <= 2))
    grown = selector.cut([first, _click(900, green[np.argsort(np.abs(x[green] - 1.5))])], selected)
    np.testing.assert_array_equal(grown, selected | ((x > 1) & (x <= 2)))
    blue_end = np.flatnonzero(x > 2)[np.argsort(x[x > 2])]
    np.testing.assert_array_equal(selector.cut([first, _click(900, blue_end)], selected), selected)


def test_a_later_positive_click_adds_no_gaussian_many_times_the_median_size():
    """A is selected (:func:`test_a_first_click_where_the_masks_hold_the_scene_is_cut_from_its_views_frame`)
    and one of the green Gaussians beside it is 20 times the median size: a positive click
    on the green adds the rest of the green and not that one (haze drawn over what lies
    around an object; the first click's cut decides it)."""
    g, x, a, frame = _bar_in_a_frame()
    green = np.flatnonzero((x > 1) & (x <= 2))
    large = green[np.argmin(np.abs(x[green] - 1.2))]
    log_scales = g.log_scales.clone()
    log_scales[large] += float(np.log(20.0))
    g = replace(g, log_scales=log_scales)
    selector = ClickSelector(g, np.full(900, 7, np.uint8), _regions(900, [np.arange(900)]))
    first = replace(_click(900, a[np.argsort(np.abs(x[a]))]), frame=frame)
    selected = selector.select([first])
    np.testing.assert_array_equal(selected, np.abs(x) <= 1)
    grown = selector.cut([first, _click(900, green[np.argsort(np.abs(x[green] - 1.5))])], selected)
    expected = selected | ((x > 1) & (x <= 2))
    expected[large] = False
    np.testing.assert_array_equal(grown, expected)


def test_a_positive_click_beyond_reach_lands_on_its_part_where_the_selection_draws_a_sliver():
    """A is selected (:func:`test_a_first_click_where_the_masks_hold_the_scene_is_cut_from_its_views_frame`).
    A positive click on the green, beyond ``part_reach`` and within ``missed_reach`` spacings
    of A's end, whose pixel one of A's Gaussians also draws with a twentieth of the click's
    weight (a blurred rim), lands on the green: it adds the green and none of the blue. Where
    A draws most of the pixel, the click lands on A, and what it shows beyond the reach stays
    out (what a gap in a statue shows behind it)."""
    g, x, a, frame = _bar_in_a_frame()
    selector = ClickSelector(g, np.full(900, 7, np.uint8), _regions(900, [np.arange(900)]))
    first = replace(_click(900, a[np.argsort(np.abs(x[a]))]), frame=frame)
    selected = selector.select([first])
    np.testing.assert_array_equal(selected, np.abs(x) <= 1)
    green = np.flatnonzero((x > 1) & (x <= 2))
    on_green = green[np.argsort(np.abs(x[green] - 1.45))][:12]
    gap = selector._gap(selected, on_green) / selector.graph.spacing
    assert selector.options.part_reach < gap.min() and gap.max() < selector.options.missed_reach
    rim = a[np.argmax(x[a])]
    for rim_weight, expected in ((0.3, selected | ((x > 1) & (x <= 2))), (20.0, selected)):
        weights = np.zeros(900)
        weights[on_green[:4]], weights[on_green[4:]], weights[rim] = 1.0, 0.2, rim_weight
        click = ClickEvidence(weights, True)
        assert rim in click.seeds(selector.options.seed_share)
        np.testing.assert_array_equal(selector.cut([first, click], selected), expected)


def test_a_positive_click_on_the_edge_adds_the_part_the_first_cut_missed_beyond_a_gap():
    """A red bar (-1 < x <= 2) between blue ends, the clicked view's frame on the blue
    (|x| > 2.5), with no Gaussian over ``gap`` beyond A's end (x = 1): the first click on A
    selects A alone, and P (the red beyond the gap) is missed, as the first cut missed a
    bronze head's crown. A positive click whose pixel A's end and P's start share adds none of
    its seeds by the edge's rule (they lie beyond ``part_reach``), so it carves P from them:
    all of P, none of the blue. Where the gap is wider than ``missed_reach`` spacings, the
    click adds nothing (what lies that far beyond the edge may show through from behind)."""
    for gap, adds in ((0.4, True), (0.9, False)):
        rng = np.random.default_rng(0)
        x = rng.uniform(-3, 3, 900)
        x = np.where((x > 1) & (x <= 1 + gap), x + gap, x)
        xyz = np.stack([x, rng.normal(0, 0.2, 900), rng.normal(0, 0.2, 900)], 1)
        red = (x > -1) & (x <= 2)
        rgb = np.where(red[:, None], [200, 30, 30], [30, 30, 200]).astype(np.uint8)
        g = gaussians_from_points(xyz, rgb, initial_opacity=0.9)
        selector = ClickSelector(g, np.full(900, 7, np.uint8), _regions(900, [np.arange(900)]))
        spacings = gap / selector.graph.spacing
        assert 4 < spacings < selector.options.missed_reach if adds else spacings > selector.options.missed_reach
        a, part = np.flatnonzero((x > -1) & (x <= 1)), np.flatnonzero((x > 1) & (x <= 2))
        first = replace(_click(900, a[np.argsort(np.abs(x[a]))]), frame=np.where(np.abs(x) > 2.5, 1.0, 0.0))
        selected = selector.select([first])
        np.testing.assert_array_equal(selected, (x > -1) & (x <= 1))
        rim = np.concatenate([a[np.argsort(-x[a])][:3], part[np.argsort(x[part])][:3]])
        on_edge = ClickEvidence(np.isin(np.arange(900), rim).astype(float), True)
        np.testing.assert_array_equal(selector.cut([first, on_edge], selected), red if adds else selected)


def _bar_colours(x: np.ndarray) -> np.ndarray:
    """(N, 3) uint8 colours of a bar along ``x`` (N,): blue to -1, red to 0.5, yellow to 1.5,
    green beyond."""
    bands = [(x <= -1)[:, None], (x <= 0.5)[:, None], (x <= 1.5)[:, None]]
    rgb = np.select(bands, [np.array([30, 30, 200]), np.array([200, 30, 30]), np.array([200, 200, 30])], [30, 200, 30])
    return rgb.astype(np.uint8)


def test_a_positive_click_of_a_colour_at_the_frame_cuts_the_object_again_to_the_frame():
    """The object is red (-1 < x <= 0.5), yellow (to 1.5) and green (to 3), beside blue, and
    the clicked view's frame shows both ends of the bar (|x| > 2.5): the object reaches the
    frame on the right, as DTU's house does. The selection holds the red and a quarter of the
    rest. A positive click on the green, whose colour the frame holds, says that the object
    reaches the frame there: cut again from all the seeds, it takes all of the object, the
    yellow nearer the first click too, and none of the blue. Where the frame shows the blue
    end alone, the same click carves its cell, and the yellow nearer the first click's
    seeds than its own stays out."""
    rng = np.random.default_rng(0)
    x = rng.uniform(-3, 3, 900)
    xyz = np.stack([x, rng.normal(0, 0.2, 900), rng.normal(0, 0.2, 900)], 1)
    g = gaussians_from_points(xyz, _bar_colours(x), initial_opacity=0.9)
    selector = ClickSelector(g, np.full(900, 7, np.uint8), _regions(900, [np.arange(900)]))
    red, quarter = np.flatnonzero((x > -1) & (x <= 0.5)), np.arange(900) % 4 == 0
    first = replace(_click(900, red[np.argsort(np.abs(x[red]))]), frame=np.where(np.abs(x) > 2.5, 1.0, 0.0))
    np.testing.assert_array_equal(selector.select([first]), (x > -1) & (x <= 0.5))
    before = (x > -1) & ((x <= 0.5) | quarter)
    green = np.flatnonzero((x > 1.5) & ~quarter)
    on_green = _click(900, green[np.argsort(np.abs(x[green] - 2.0))])
    np.testing.assert_array_equal(selector.cut([first, on_green], before), x > -1)
    inside = replace(first, frame=np.where(x < -2.5, 1.0, 0.0))
    carved = selector.cut([inside, on_green], before)
    assert carved[x > 1.5].all() and not carved[(x > 0.5) & (x <= 1.0)].all() and not carved[x <= -1].any()


def test_a_positive_click_on_a_floater_far_from_a_framed_selection_changes_nothing():
    """The bar of the test above with dark spots all along it and five dark Gaussians floating
    40 units above its blue end (a floater in front of the object in another view); the
    clicked view's frame on both ends. The first click, on the red and two of its dark spots,
    selects the red band. A positive click on the floater, of a colour the selection has,
    would carve its cell and add it: it lies farther from the selection than the selection is
    wide, so the click changes nothing."""
    rng = np.random.default_rng(0)
    x = np.r_[rng.uniform(-3, 3, 900), np.full(5, -2.8)]
    y = np.r_[rng.normal(0, 0.2, 900), 40 + rng.normal(0, 0.05, 5)]
    xyz = np.stack([x + np.r_[np.zeros(900), rng.normal(0, 0.05, 5)], y, rng.normal(0, 0.2, 905)], 1)
    bar = np.arange(905) < 900
    rgb = _bar_colours(x)
    dark = (np.arange(905) % 10 == 0) | ~bar
    rgb[dark] = [20, 20, 20]
    g = gaussians_from_points(xyz, rgb, initial_opacity=0.9)
    selector = ClickSelector(g, np.full(905, 7, np.uint8), _regions(905, [np.arange(905)]))
    band = np.flatnonzero(bar & (x > -1) & (x <= 0.5))
    near = band[np.argsort(np.abs(x[band]))]
    seeds = np.r_[near[~dark[near]][:3], near[dark[near]][:2]]
    first = replace(_click(905, seeds), frame=np.where(bar & (np.abs(x) > 2.5), 1.0, 0.0))
    before = selector.select([first])
    assert before[band].mean() > 0.85 and not before[~np.isin(np.arange(905), band)].any()
    np.testing.assert_array_equal(selector.cut([first, _click(905, np.flatnonzero(~bar))], before), before)


def test_a_negative_click_on_the_selections_rim_takes_out_its_seeds_of_the_rests_colour_alone():
    """The masks hold A (red) apart from B (blue), and the selection holds A and five of B's
    Gaussians nearest to A (a spill over the background). A negative click whose pixel A's
    rim and B's near edge share (each half of its weight) takes out none of A: the graph
    beyond its seeds says nothing of where A ends. One whose pixel the spill and the rest of
    B share takes out the spill it lands on, of B's colour, and nothing else. A negative
    click on A alone still takes out its side of A."""
    g, a, b = _two_blobs_on_a_backdrop()
    n = len(g)
    x = g.means[:, 0].numpy()
    selector = ClickSelector(g, np.full(n, 7, np.uint8), _regions(n, [a, b]))
    first = _click(n, a[np.argsort(x[a])])
    spill = b[np.argsort(x[b])][:5]
    before = selector.select([first])
    before[spill] = True
    rim = np.concatenate([a[np.argsort(-x[a])][:5], b[np.argsort(x[b])][5:10]])
    on_rim = ClickEvidence(np.isin(np.arange(n), rim).astype(float), False)
    np.testing.assert_array_equal(selector.cut([first, on_rim], before), before)
    on_spill = np.zeros(n)
    on_spill[spill[:3]], on_spill[b[np.argsort(x[b])][10:13]] = 2.0, 1.0
    on_spill = ClickEvidence(on_spill, False)
    expected = before.copy()
    expected[spill[:3]] = False
    np.testing.assert_array_equal(selector.cut([first, on_spill], before), expected)
    on_a = _click(n, a[np.argsort(-x[a])], positive=False)
    assert not selector.cut([first, on_a], before)[a[np.argsort(-x[a])][:5]].any()


def test_a_negative_click_within_the_blur_of_the_selections_rim_takes_out_none_of_the_object():
    """The masks hold A (red) apart and the selection is A. A negative click on A's far end,
    its seeds all A's, lands where the selection draws A's rim: one pixel inside the edge of
    what it draws, where its seeds' footprints spread three (the model draws A's rim as a blur
    beyond A's edge in the photo): it takes out none of A. The same click ten pixels inside
    the edge takes out its side of A, as a click on a part the masks joined to A does; so does
    a click without a view to measure it in."""
    g, a, b = _two_blobs_on_a_backdrop()
    n = len(g)
    x = g.means[:, 0].numpy()
    selector = ClickSelector(g, np.full(n, 7, np.uint8), _regions(n, [a, b]))
    first = _click(n, a[np.argsort(x[a])])
    before = selector.select([first])
    assert before[a].all() and not before[b].any()
    far_end = _click(n, a[np.argsort(-x[a])], positive=False)
    blurred = replace(far_end, spread=np.full(n, 3.0), inside=lambda selected: 1.0)
    np.testing.assert_array_equal(selector.cut([first, blurred], before), before)
    for deep in (replace(blurred, inside=lambda selected: 10.0), far_end):
        assert not selector.cut([first, deep], before)[a[np.argsort(-x[a])][:5]].any()


def test_a_click_measures_how_deep_it_lies_inside_a_selection_and_its_seeds_blur():
    """Known answers of ``spread`` and ``inside``: a Gaussian of standard deviation 0.5 at depth
    5 on the axis of a focal length of 100 spreads 10 pixels, one of 0.2 at depth 8, off the
    axis by 3 and 3, 2.5 stretched by the perspective's slant (1 + 18 / 64), each widened by the
    projection's low-pass filter (``EPS_2D`` pixels squared). A click at the nearer one's centre
    lies as deep inside what it draws as the disc where its alpha (0.99 at the centre) is at
    least one half reaches, and nowhere inside what the other or nothing draws."""
    g = gaussians_from_points(
        np.array([[0.0, 0.0, 5.0], [3.0, -3.0, 8.0]]), np.full((2, 3), 128, np.uint8), initial_opacity=0.99
    )
    g.log_scales = torch.log(torch.tensor([0.5, 0.2]))[:, None].repeat(1, 3)
    camera = PinholeCamera(128, 128, 100.0, 100.0, 64.0, 64.0)
    seen = click_evidence(g, camera, np.eye(4)[:3], 64.0, 64.0, positive=False)
    np.testing.assert_allclose(seen.spread, np.sqrt(np.array([10.0**2, 2.5**2 * (1 + 18 / 64)]) + EPS_2D), rtol=1e-5)
    half_alpha = seen.spread[0] * np.sqrt(2 * np.log(2 * 0.99))
    assert seen.inside(np.array([True, False])) == pytest.approx(half_alpha, abs=1.0)
    assert seen.inside(np.array([False, True])) == 0 and seen.inside(np.zeros(2, bool)) == 0


def test_a_positive_click_on_the_selections_rim_brings_back_nothing_a_negative_click_took():
    """The masks join A and B, of one colour, where they touch; a negative click on B's far end
    takes out B's far part. A positive click whose pixel the selection's rim and the part taken
    out share (each half of its weight) adds at most its own seeds: the graph beyond them says
    nothing of where the object ends, and what the negative click fixed stays fixed."""
    rng = np.random.default_rng(0)
    xyz = np.concatenate([rng.normal(0, 0.3, (200, 3)), rng.normal(0, 0.3, (200, 3)) + [1.2, 0, 0]])
    a, b = np.arange(200), np.arange(200, 400)
    g = _on_a_backdrop(xyz, np.tile([200, 30, 30], (400, 1)))
    n = len(g)
    x = g.means[:, 0].numpy()
    selector = ClickSelector(g, np.full(n, 7, np.uint8), _regions(n, [np.concatenate([a, b])]))
    first = _click(n, a[np.argsort(x[a])])
    against = _click(n, b[np.argsort(-x[b])], positive=False)
    before = selector.select([first, against])
    taken = np.flatnonzero(~before[b]) + 200
    assert before[a].all() and len(taken) > 100
    kept = np.flatnonzero(before)
    rim = np.concatenate([kept[np.argsort(-x[kept])][:5], taken[np.argsort(x[taken])][:5]])
    after = selector.cut([first, against, ClickEvidence(np.isin(np.arange(n), rim).astype(float), True)], before)
    assert after[before].all() and np.isin(np.flatnonzero(after & ~before), rim).all()


def test_carving_decides_what_no_clicked_view_shows_by_the_cut():
    """A bar along x, one region in every view: C (x < -1.5), A (red, the middle) and B (x >
    1.5); the clicked view shows A and B, not C. A click on A, a negative one on B's far end:
    C lies nearer A along the graph, outside the negative click's own cell, yet no clicked
    view shows it, so the cut decides it by its colour: blue like B, it goes with B; red
    like A, it stays."""
    rng = np.random.default_rng(0)
    x = rng.uniform(-3, 3, 900)
    xyz = np.stack([x, rng.normal(0, 0.2, 900), rng.normal(0, 0.2, 900)], 1)
    c, a, b = np.flatnonzero(x < -1.5), np.flatnonzero(np.abs(x) <= 1.5), np.flatnonzero(x > 1.5)
    shown = np.where(x < -1.5, 0.0, 1.0)
    clicks = [_click(900, a[np.argsort(np.abs(x[a]))], shown=shown), _click(900, b[np.argsort(-x[b])], False, shown)]
    for c_like_a in (False, True):
        red = x <= 1.5 if c_like_a else np.abs(x) <= 1.5
        g = gaussians_from_points(
            xyz, np.where(red[:, None], [200, 30, 30], [30, 30, 200]).astype(np.uint8), initial_opacity=0.9
        )
        selector = ClickSelector(g, np.full(900, 7, np.uint8), _regions(900, [np.arange(900)]))
        carved = selector.select(clicks)
        assert carved[a].all() and not carved[b].any()
        assert carved[c].all() if c_like_a else not carved[c].any()


def test_the_first_carving_click_takes_of_what_no_view_shows_only_what_looks_like_its_part():
    """A bar along x, one region in every view: A (x <= 1) and B (blue, x > 1); the clicked
    view hides A's end next to B (0 < x <= 1), as a view of DTU's house hides its back. A
    click on A's far end, a negative one on B beside the hidden end: the hidden end lies
    nearer the negative click along the graph, yet red like A it stays; blue like B, it goes
    with B."""
    rng = np.random.default_rng(0)
    x = rng.uniform(-6, 3, 1200)
    xyz = np.stack([x, rng.normal(0, 0.2, 1200), rng.normal(0, 0.2, 1200)], 1)
    a, b, hidden = np.flatnonzero(x <= 1), np.flatnonzero(x > 1), np.flatnonzero((x > 0) & (x <= 1))
    shown = np.where((x > 0) & (x <= 1), 0.0, 1.0)
    clicks = [_click(1200, a[np.argsort(x[a])], shown=shown), _click(1200, b[np.argsort(x[b])], False, shown)]
    for hidden_like_a in (True, False):
        red = x <= (1 if hidden_like_a else 0)
        rgb = np.where(red[:, None], [200, 30, 30], [30, 30, 200]) + rng.integers(-12, 13, (1200, 3))
        g = gaussians_from_points(xyz, np.clip(rgb, 0, 255).astype(np.uint8), initial_opacity=0.9)
        carved = ClickSelector(g, np.full(1200, 7, np.uint8), _regions(1200, [np.arange(1200)])).select(clicks)
        assert not carved[b].any() and carved[a[x[a] < -1]].all()
        assert carved[hidden].all() if hidden_like_a else not carved[hidden].any()


def test_a_negative_click_on_what_the_vote_holds_loosely_does_not_carve():
    """A (red, x from 0 to 4, its far end x > 3 orange) fills most of every view, and the masks
    hold it apart from a grey backdrop beyond it (x = 5.5), so the vote holds the scene yet
    says where A ends; S (orange, x = 4.2) lies in A's region in half the views and in the
    backdrop's in the rest. The clicked view shows A's near half and S. A negative click on S,
    held at one half, is a negative click as with masks: S goes, and A's far end, which no
    clicked view shows and which lies nearer S along the graph and in colour, stays. Where the
    masks hold S in A's region in every view, the same click carves, and the far end goes
    with S (DTU's house, whose back a click on its spill in a corner took)."""
    rng = np.random.default_rng(2)
    xyz = np.concatenate(
        [
            rng.uniform([0, -0.2, -0.2], [4, 0.2, 0.2], (400, 3)),
            rng.normal([4.2, 0, 0], 0.15, (20, 3)),
            rng.normal([5.5, 0, 0], 0.2, (60, 3)),
        ]
    )
    n, a, s = len(xyz), np.arange(400), np.arange(400, 420)
    rgb = np.concatenate([np.tile([200, 30, 30], (420, 1)), np.full((60, 3), 128)])
    rgb[(xyz[:, 0] > 3) & (np.arange(n) < 420)] = [200, 150, 30]
    g = gaussians_from_points(
        xyz, np.clip(rgb + rng.integers(-12, 13, rgb.shape), 0, 255).astype(np.uint8), initial_opacity=0.9
    )
    near, far = a[xyz[a, 0] < 1], a[xyz[a, 0] > 3]
    shown = np.where(xyz[:, 0] > 2, 0.0, 1.0)
    shown[s] = 1.0
    clicks = [_click(n, near, shown=shown), _click(n, s, positive=False, shown=shown)]
    for s_in_a in (False, True):
        regions = _views_split([np.concatenate([a, s])], 3, [np.concatenate([a, s]) if s_in_a else a], 3, n)
        selector = ClickSelector(g, np.full(n, 7, np.uint8), regions)
        share, _, _ = selector.views_vote(clicks[:1], None)
        assert selector.vote.holds_the_scene(share, clicks[0], selector.options.seen_share)
        after = selector.select(clicks)
        assert after[near].all() and after[s].mean() < 0.1
        assert not after[far].any() if s_in_a else after[far].all()


def test_the_click_that_starts_the_carving_decides_the_earlier_negative_clicks_cells():
    """A (red), C (blue, its half towards A red) and B (green), in a row and one region in
    half the views; the other half hold A and B as one region and C in the background. The
    vote holds the scene. A negative click on C's blue half, held at one half, is one as with
    masks: the blue half goes, the red half (like A) stays. A negative click on B, held
    firmly, starts the carving, which decides C's side too: C's red half goes with B."""
    rng = np.random.default_rng(0)
    xyz = np.concatenate([rng.normal([x, 0, 0], 0.3, (200, 3)) for x in (0, -3, 3)])
    n, a, c, b = 600, np.arange(200), np.arange(200, 400), np.arange(400, 600)
    rgb = np.concatenate([np.tile(colour, (200, 1)) for colour in ([200, 30, 30], [30, 30, 200], [30, 200, 30])])
    red_c, blue_c = c[xyz[c, 0] > -3], c[xyz[c, 0] <= -3]
    rgb[red_c] = [200, 30, 30]
    g = gaussians_from_points(
        xyz, np.clip(rgb + rng.integers(-12, 13, rgb.shape), 0, 255).astype(np.uint8), initial_opacity=0.9
    )
    selector = ClickSelector(
        g, np.full(n, 7, np.uint8), _views_split([np.arange(n)], 3, [np.concatenate([a, b])], 3, n)
    )
    clicks = [_click(n, a), _click(n, blue_c[np.argsort(xyz[blue_c, 0])], False), _click(n, b, False)]
    share, _, _ = selector.views_vote(clicks[:1], None)
    assert selector.vote.holds_the_scene(share, clicks[0], selector.options.seen_share)
    with_masks = selector.select(clicks[:2])
    assert with_masks[a].all() and with_masks[red_c].all() and not with_masks[blue_c].any() and with_masks[b].all()
    carved = selector.select(clicks)
    assert carved[a].all() and not carved[c].any() and not carved[b].any()


def _spill():
    """A long object A of 400 Gaussians (x from 0 to 4) and a spill F of 60 of its colour beside
    its far end (x = 4.6), which three of six views' masks give to A, all under one label, on
    :func:`_on_a_backdrop`: (selector, A, F, A's 5 Gaussians nearest x = 0, A's 80 nearest F)."""
    rng = np.random.default_rng(1)
    xyz = np.concatenate(
        [rng.uniform([0, -0.2, -0.2], [4, 0.2, 0.2], (400, 3)), rng.normal([4.6, 0, 0], 0.15, (60, 3))]
    )
    g = _on_a_backdrop(xyz, np.tile([200, 30, 30], (460, 1)))
    a, f = np.arange(400), np.arange(400, 460)
    order = np.argsort(xyz[a, 0])
    n = len(g)
    halves = _regions(n, [np.concatenate([a, f])], views=3), _regions(n, [a], views=3)
    regions = RegionWeights(
        sp.vstack([halves[0].matrix, halves[1].matrix]).tocsr(),
        np.concatenate([halves[0].view, halves[1].view + 3]),
        np.concatenate([halves[0].label, halves[1].label]),
        np.zeros(2 * len(halves[0].view), np.uint8),
        ("m",),
    )
    return ClickSelector(g, np.full(n, 7, np.uint8), regions), a, f, a[order[:5]], a[order[-80:]]


def test_a_negative_click_on_a_spill_takes_the_spill_and_not_the_objects_far_end():
    """F is selected with A; a negative click on F takes F, while A's far end, nearer F than
    the positive click along the graph but held in A's regions by every view, stays."""
    selector, a, f, near_end, far_end = _spill()
    n = len(selector.labels)
    first = selector.select([_click(n, near_end)])
    assert first[a].all() and first[f].all()
    after = selector.select([_click(n, near_end), _click(n, f, positive=False)])
    assert after[far_end].all() and after[a].mean() > 0.99
    assert after[f].mean() < 0.1


def _views_split(groups_a: list[np.ndarray], views_a: int, groups_b: list[np.ndarray], views_b: int, n: int):
    """Region weights of ``views_a`` views with the regions ``groups_a`` and ``views_b`` views
    with ``groups_b`` (as :func:`_regions`)."""
    first, second = _regions(n, groups_a, views=views_a), _regions(n, groups_b, views=views_b)
    return RegionWeights(
        sp.vstack([first.matrix, second.matrix]).tocsr(),
        np.concatenate([first.view, second.view + views_a]),
        np.concatenate([first.label, second.label]),
        np.zeros(len(first.view) + len(second.view), np.uint8),
        ("m",),
    )


def test_the_colour_model_favours_the_colours_of_its_set_and_learns_nothing_from_none():
    """Red inside, blue outside: red Gaussians get the clipped ratio +3, blue ones -3, a green
    that neither set holds about 0; an empty set teaches nothing (0 everywhere)."""
    rgb = np.array([[0.8, 0.1, 0.1]] * 5 + [[0.1, 0.1, 0.8]] * 5 + [[0.1, 0.7, 0.1]])
    model = ColourModel(rgb, np.ones(len(rgb)), bins=12)
    red = np.arange(len(rgb)) < 5
    blue = (np.arange(len(rgb)) >= 5) & (np.arange(len(rgb)) < 10)
    ratio = model.ratio(red, blue)
    assert np.allclose(ratio[red], ColourModel.CLIP) and np.allclose(ratio[blue], -ColourModel.CLIP)
    assert abs(ratio[-1]) < 0.1
    assert not model.ratio(np.zeros(len(rgb), bool), blue).any()


def test_the_objects_colour_carries_the_cut_over_a_split_the_views_half_make():
    """A red object whose far half two of five views hold to it and three join to the blue
    table beside it (a head whose back the masks give to the table), among green surroundings:
    the views alone leave most of the far half out (it falls 40% in the object's regions); the colour
    model learned from the cut brings it in, and leaves the blue table out."""
    rng = np.random.default_rng(3)
    near, far, table = (rng.normal([x, 0, 0], [0.25, 0.3, 0.3], (200, 3)) for x in (0.0, 0.8, 1.8))
    rest = rng.uniform([-6, -6, -6], [6, 6, -3], (600, 3))
    rgb = np.concatenate(
        [np.tile(c, (k, 1)) for c, k in (([200, 30, 30], 400), ([30, 30, 200], 200), ([30, 180, 40], 600))]
    )
    g = gaussians_from_points(np.concatenate([near, far, table, rest]), rgb.astype(np.uint8), initial_opacity=0.9)
    n = len(g)
    o_near, o_far, t = np.arange(200), np.arange(200, 400), np.arange(400, 600)
    regions = _views_split([np.concatenate([o_near, o_far]), t], 2, [o_near, np.concatenate([o_far, t])], 3, n)
    labels = np.zeros(n, np.uint8)
    labels[:600] = 7
    plain = ClickSelector(g, labels, regions, ClickOptions(appearance_rounds=0)).select([_click(n, o_near)])
    assert plain[o_near].all() and plain[o_far].mean() < 0.25 and not plain[t].any()
    coloured = ClickSelector(g, labels, regions).select([_click(n, o_near)])
    assert (
        coloured[o_near].all() and coloured[o_far].mean() > 0.9 and not coloured[t].any() and not coloured[600:].any()
    )


def test_a_clicks_seeds_pass_over_a_backdrop_gaussian_drawn_mostly_elsewhere():
    """Weights 5, 3, 1, 1 at the click: the seeds carrying 80% are the first two; when the
    second draws a ten-thousandth of its weight in the view at the click (a large Gaussian of
    the backdrop), 80% of the rest's 7 is carried by the first and the third; when all draw so
    little there, all count."""
    weights = np.array([5.0, 3.0, 1.0, 1.0])
    assert sorted(ClickEvidence(weights, True).seeds(0.8)) == [0, 1]
    local = np.array([0.2, 1e-4, 0.05, 0.3])
    assert sorted(ClickEvidence(weights, True, local=local).seeds(0.8, 0.001)) == [0, 2]
    assert sorted(ClickEvidence(weights, True, local=np.full(4, 1e-4)).seeds(0.8, 0.001)) == [0, 1]


def test_a_positive_click_never_takes_out_and_a_negative_click_never_adds():
    """Ten clicks at random Gaussians of the spill's scene, each for or against at random:
    every selection holds the one before it after a positive click and lies inside it after a
    negative one."""
    selector, a, f, near_end, _ = _spill()
    n = len(selector.labels)
    rng = np.random.default_rng(2)
    clicks = [_click(n, near_end)]
    before = selector.select(clicks)
    for _ in range(10):
        click = _click(n, rng.choice(n, 5, replace=False), positive=bool(rng.random() < 0.5))
        clicks.append(click)
        after = selector.cut(clicks, before)
        assert (after >= before).all() if click.positive else (after <= before).all()
        before = after


def test_a_positive_click_adds_a_part_no_label_holds_and_keeps_what_was_selected():
    g, a, b = _two_blobs()
    n = len(g)
    labels = np.zeros(n, np.uint8)
    labels[a] = 3  # B carries no label: the 3D labels lost it
    selector = ClickSelector(g, labels, _regions(n, [a, b]))
    first = selector.select([_click(n, a)])
    assert first[a].all() and not first[b].any()
    both = selector.cut([_click(n, a), _click(n, b)], first)
    assert both[a].all() and both[b].all()
    assert np.array_equal(both, selector.select([_click(n, a), _click(n, b)]))


def test_a_positive_click_adds_a_part_the_masks_hold_apart_and_nothing_far_off():
    """A red ball with a pale cap on its top and a blue wall behind: three views hold the cap
    as a region of its own, three under the background with the wall (a highlight on a
    bronze head, where the sky's reflection joins the sky). The first click takes the ball
    alone; a click on the cap adds all of it, where the views' vote alone adds its five
    seeds, and nothing of the wall."""
    rng = np.random.default_rng(0)
    ball = rng.normal(0, 0.3, (200, 3))
    cap = rng.normal(0, 0.08, (30, 3)) + [0, 0, 0.35]
    wall = np.c_[rng.uniform(-2, 2, 200), np.full(200, 3.0), rng.uniform(-2, 2, 200)]
    rgb = np.repeat(np.array([[200, 30, 30], [230, 230, 220], [30, 30, 200]]), [200, 30, 200], axis=0)
    rgb = np.clip(rgb + rng.normal(0, 8, rgb.shape), 0, 255).astype(np.uint8)  # colours vary, as fitted ones do
    g = gaussians_from_points(np.concatenate([ball, cap, wall]), rgb, initial_opacity=0.9)
    a, c, b = np.arange(200), np.arange(200, 230), np.arange(230, 430)
    n = len(g)
    both_kinds = _regions(n, [a, c], views=3)
    background = _regions(n, [a], views=3)
    regions = RegionWeights(
        sp.vstack([both_kinds.matrix, background.matrix]).tocsr(),
        np.concatenate([both_kinds.view, background.view + 3]),
        np.concatenate([both_kinds.label, background.label]),
        np.zeros(len(both_kinds.view) + len(background.view), np.uint8),
        ("m",),
    )
    labels = np.zeros(n, np.uint8)
    labels[a] = 1
    selector = ClickSelector(g, labels, regions)
    first = selector.select([_click(n, a)])
    assert first[a].all() and not first[c].any() and not first[b].any()
    after = selector.cut([_click(n, a), _click(n, c)], first)
    assert after[a].all() and after[c].all() and not after[b].any()
    no_growth = ClickSelector(g, labels, regions, ClickOptions(split_full=1e6))
    assert no_growth.cut([_click(n, a), _click(n, c)], first)[c].sum() <= 5


def test_a_positive_click_deep_in_a_part_the_masks_gave_to_the_surroundings_adds_it():
    """A red column and a blue wall just behind it; every view's masks hold the column's
    bottom half as the object and its top half under the background with the wall (a box's
    lid joined to the bench). The first click takes the bottom; a click at the column's top,
    far from the bottom, adds the top, its side the clicked view hides too, and nothing of
    the wall, and a negative click on the
    wall then keeps it. Bounded by all the views hold off (the rule for a part beside the
    selection, here with a reach that takes the seeds in) it would add little more than its
    five seeds."""
    rng = np.random.default_rng(0)
    bottom = np.c_[rng.normal(0, 0.15, (200, 2)), rng.uniform(0, 1, 200)]
    top = np.c_[rng.normal(0, 0.15, (200, 2)), rng.uniform(1, 2, 200)]
    wall = np.c_[rng.uniform(-1, 1, 300), np.full(300, 0.35), rng.uniform(0, 2, 300)]
    rgb = np.repeat(np.array([[200, 30, 30], [200, 30, 30], [30, 30, 200]]), [200, 200, 300], axis=0)
    rgb = np.clip(rgb + rng.normal(0, 8, rgb.shape), 0, 255).astype(np.uint8)
    g = gaussians_from_points(np.concatenate([bottom, top, wall]), rgb, initial_opacity=0.9)
    n = len(g)
    a, t, w = np.arange(200), np.arange(200, 400), np.arange(400, 700)
    labels = np.zeros(n, np.uint8)
    labels[a] = 1
    tip = t[np.argsort(-g.means.numpy()[t, 2])]  # the click at the top's far end
    front = (g.means.numpy()[:, 1] < 0) | (np.arange(n) >= 400)  # its view shows the top's front half
    clicks = [_click(n, a), _click(n, tip, shown=front.astype(float))]
    selector = ClickSelector(g, labels, _regions(n, [a]))
    first = selector.select(clicks[:1])
    assert first[a].all() and not first[t].any() and not first[w].any()
    after = selector.cut(clicks, first)
    assert after[a].all() and after[t].mean() > 0.95 and not after[w].any()
    # a negative click on the wall takes out only what lies on its side: the top stays,
    # although the views' vote holds it off the object
    again = selector.cut([*clicks, _click(n, w[np.argsort(g.means.numpy()[w, 2])], positive=False)], after)
    assert np.array_equal(again, after)
    beside = ClickSelector(g, labels, _regions(n, [a]), ClickOptions(part_reach=100.0))
    assert beside.cut(clicks, first)[t].sum() < 20


def _column_given_half_away(apart: np.ndarray | None = None):
    """The column of the test above and its wall, the masks holding the bottom and giving the
    top to the background; with Gaussians of the column's colour at ``apart`` (M, 3) too. The
    model and the bottom, top and ``apart`` indices."""
    rng = np.random.default_rng(0)
    apart = np.zeros((0, 3)) if apart is None else apart
    bottom = np.c_[rng.normal(0, 0.15, (200, 2)), rng.uniform(0, 1, 200)]
    top = np.c_[rng.normal(0, 0.15, (200, 2)), rng.uniform(1, 2, 200)]
    wall = np.c_[rng.uniform(-1, 1, 300), np.full(300, 0.35), rng.uniform(0, 2, 300)]
    rgb = np.repeat(np.array([[200, 30, 30], [30, 30, 200], [200, 30, 30]]), [400, 300, len(apart)], axis=0)
    rgb = np.clip(rgb + rng.normal(0, 8, rgb.shape), 0, 255).astype(np.uint8)
    g = gaussians_from_points(np.concatenate([bottom, top, wall, apart]), rgb, initial_opacity=0.9)
    return g, np.arange(200), np.arange(200, 400), np.arange(700, 700 + len(apart))


def test_a_positive_click_deep_in_a_part_adds_it_though_a_seed_touches_the_selection():
    """A click at the column's top, far from the bottom, one of whose four seeds lies in the
    top just over the bottom: most of its weight lands deep inside the top, and the top comes
    whole. Read as a click beside the selection (any seed there), the part held off all
    around its near seed added a few Gaussians."""
    g, a, t, _ = _column_given_half_away()
    n, z = len(g), g.means.numpy()[:, 2]
    labels = np.zeros(n, np.uint8)
    labels[a] = 1
    selector = ClickSelector(g, labels, _regions(n, [a]))
    first = selector.select([_click(n, a)])
    left = t[~first[t]]
    weights = np.zeros(n)
    weights[t[np.argsort(-z[t])[:3]]] = 1.0
    weights[left[np.argmin(cKDTree(g.means.numpy()[first]).query(g.means.numpy()[left])[0])]] = 1.0
    after = selector.cut([_click(n, a), ClickEvidence(weights, True)], first)
    assert after[a].all() and after[t].mean() > 0.95


def test_a_positive_click_adds_nothing_the_graph_does_not_join_to_the_selection():
    """The column and, far behind it, a ball of its colour; a click on the bottom's rim whose
    pixel the ball's edge draws too (three of its five seeds: a ball behind a box of its
    colour) adds nothing of the ball, whose Gaussians the graph joins to nothing selected: an
    object is one piece. The ball came whole, each of its Gaussians grown from the seeds deep
    inside. A click at the top's far end still adds the top, and none of the ball."""
    ball = np.random.default_rng(3).normal(0, 0.2, (150, 3)) + [0.0, 4.0, 1.0]
    g, a, t, b = _column_given_half_away(ball)
    n, z = len(g), g.means.numpy()[:, 2]
    labels = np.zeros(n, np.uint8)
    labels[a] = 1
    weights = np.zeros(n)
    weights[a[np.argsort(-z[a])[:2]]] = 1.0
    weights[b[:3]] = 1.0
    selector = ClickSelector(g, labels, _regions(n, [a]))
    clicks = [_click(n, a), ClickEvidence(weights, True)]
    first = selector.select(clicks[:1])
    rim = selector.cut(clicks, first)
    assert rim[a].all() and not rim[b].any()
    after = selector.cut([*clicks, _click(n, t[np.argsort(-z[t])])], rim)
    assert after[t].mean() > 0.95 and not after[b].any()


def test_a_part_added_from_deep_inside_keeps_only_the_hidden_side_of_its_fronts_colours():
    """A house of red, black and grey Gaussians on a grey plate, and a black slab behind the
    plate; the masks hold the house alone. A click deep in the plate adds the plate, its side
    the clicked view hides as well, and none of the slab, which the view hides too: black is
    of the house's colours, not of the plate's front. Alike to the object alone, the plate's
    hidden side brought the whole slab (a model house's plate and the black backdrop behind
    it)."""
    rng = np.random.default_rng(0)
    house = np.c_[rng.normal(0, 0.15, (200, 2)), rng.uniform(0.25, 1, 200)]
    plate = np.c_[rng.uniform(-0.6, 0.6, (200, 2)), rng.uniform(0, 0.2, 200)]
    slab = np.c_[rng.uniform(-0.6, 0.6, 200), rng.uniform(0.65, 0.8, 200), rng.uniform(0, 0.4, 200)]
    red, black, grey = [200, 30, 30], [20, 20, 20], [128, 128, 128]
    rgb = np.repeat(np.array([red, black, grey, grey, black]), [20, 90, 90, 200, 200], axis=0)
    rgb = np.clip(rgb + rng.normal(0, 6, rgb.shape), 0, 255).astype(np.uint8)
    g = gaussians_from_points(np.concatenate([house, plate, slab]), rgb, initial_opacity=0.9)
    n, xyz = len(g), g.means.numpy()
    h, p, s = np.arange(200), np.arange(200, 400), np.arange(400, 600)
    labels = np.zeros(n, np.uint8)
    labels[h] = 1
    shown = (xyz[:, 1] < 0.3) & (np.arange(n) < 400)  # the view shows the plate's front half
    deep = p[np.argsort(np.linalg.norm(xyz[p] - [0, -0.5, 0.1], axis=1))]  # at the plate's front edge
    clicks = [_click(n, h), _click(n, deep, shown=shown.astype(float))]
    selector = ClickSelector(g, labels, _regions(n, [h]))
    first = selector.select(clicks[:1])
    assert first[h].all() and not first[p].any() and not first[s].any()
    after = selector.cut(clicks, first)
    assert after[h].all() and after[p].all() and not after[s].any()


def test_a_negative_click_takes_out_what_its_word_reaches_not_all_the_views_hold_off():
    """The column of the test above with a red flap standing out of its top (a cloth hung on
    a box's lid): the views hold the top and the flap off the object, a click at the top's
    far end adds both, and a negative click on the flap beside the column then takes the
    flap. What the earlier click added goes only where the negative click's word reaches: the
    views' vote, which holds the whole top off, took 55 of its Gaussians with the flap."""
    rng = np.random.default_rng(0)
    bottom = np.c_[rng.normal(0, 0.15, (200, 2)), rng.uniform(0, 1, 200)]
    top = np.c_[rng.normal(0, 0.15, (200, 2)), rng.uniform(1, 2, 200)]
    flap = np.c_[rng.uniform(0.2, 0.8, 100), rng.normal(0, 0.03, 100), rng.normal(1.5, 0.05, 100)]
    wall = np.c_[rng.uniform(-1, 1, 300), np.full(300, 0.35), rng.uniform(0, 2, 300)]
    rgb = np.repeat(np.array([[200, 30, 30], [30, 30, 200]]), [500, 300], axis=0)
    rgb = np.clip(rgb + rng.normal(0, 8, rgb.shape), 0, 255).astype(np.uint8)
    g = gaussians_from_points(np.concatenate([bottom, top, flap, wall]), rgb, initial_opacity=0.9)
    n, means = len(g), g.means.numpy()
    a, t, f = np.arange(200), np.arange(200, 400), np.arange(400, 500)
    labels = np.zeros(n, np.uint8)
    labels[a] = 1
    clicks = [_click(n, a), _click(n, t[np.argsort(-means[t, 2])])]
    selector = ClickSelector(g, labels, _regions(n, [a]))
    after = selector.cut(clicks, selector.select(clicks[:1]))
    assert after[t].mean() > 0.9 and after[f].all()
    against = _click(n, f[np.argsort(np.abs(means[f, 0] - 0.3))], positive=False)
    again = selector.cut([*clicks, against], after)
    assert not again[f].any() and again[a].all()
    assert (after[t] & ~again[t]).sum() < 25


def _column_on_a_table(table_rgb: list[int]):
    """A red column (200 Gaussians) standing on a table (400) of colour ``table_rgb``, on
    :func:`_on_a_backdrop`; the column, the table, and the table's half behind the column
    (y > 0.3) as index arrays."""
    rng = np.random.default_rng(1)
    column = np.c_[rng.normal(0, 0.15, (200, 2)), rng.uniform(0.05, 1.5, 200)]
    table = np.c_[rng.uniform(-1.5, 1.5, (400, 2)), rng.normal(0, 0.02, 400)]
    rgb = np.repeat(np.array([[200, 30, 30], table_rgb]), [200, 400], axis=0)
    g = _on_a_backdrop(np.concatenate([column, table]), rgb)
    c, t = np.arange(200), np.arange(200, 600)
    return g, c, t, t[table[:, 1] > 0.3]


def test_a_negative_click_carves_apart_a_surface_the_masks_joined_to_the_object():
    """Every view's masks join a red column to the grey table it stands on (tools and the table
    under them as one region); the clicked view shows the table's front, not its back. A
    negative click on the front takes the whole table, the back too, and none of the column,
    and a later positive click on the column brings none of it back. Where the table has the
    column's colour, the clicks cannot tell the two apart: the click is one as with masks and
    reaches only what its view shows."""
    for table_rgb, apart in (([128, 128, 128], True), ([200, 30, 30], False)):
        g, c, t, back = _column_on_a_table(table_rgb)
        n = len(g)
        selector = ClickSelector(g, np.isin(np.arange(n), np.r_[c, t]).astype(np.uint8), _regions(n, [np.r_[c, t]]))
        front = t[np.argsort(g.means.numpy()[t, 1])]  # the table's nearest edge first
        shown = np.where(np.isin(np.arange(n), back), 0.0, 1.0)
        clicks = [_click(n, c), _click(n, front, positive=False, shown=shown)]
        first = selector.select(clicks[:1])
        assert first[c].all() and first[t].all()
        after = selector.cut(clicks, first)
        assert after[c].all() and not after[front[:100]].any()
        if apart:
            assert after[t].mean() < 0.05 and after[back].mean() < 0.05
            top = c[np.argsort(-g.means.numpy()[c, 2])]
            assert np.array_equal(selector.cut([*clicks, _click(n, top)], after), after)
        else:
            assert after[back].mean() > 0.9


def test_a_positive_click_at_the_objects_foot_does_not_bring_back_the_part_carved_apart():
    """The masks join a red column to the grey table under it (a third of every view), and a
    negative click on the table's front carves the table apart. A positive click at the
    column's foot whose pixel the table beside it draws (five grey seeds, and a tenth as much
    of one red) adds none of the table: grey is a colour the column lacks and the negative
    click's seeds have, and the click, though of the table's colour, does not undo the
    carving."""
    g, c, t, _ = _column_on_a_table([128, 128, 128])
    n = len(g)
    regions = _regions(n, [np.r_[c, t]])
    regions = replace(regions, matrix=regions.matrix @ sp.diags(np.where(np.arange(n) < 600, 1.0, 2.0)))
    selector = ClickSelector(g, np.isin(np.arange(n), np.r_[c, t]).astype(np.uint8), regions)
    xyz = g.means.numpy()
    front = t[np.argsort(xyz[t, 1])]
    clicks = [_click(n, c), _click(n, front, positive=False)]
    carved = selector.select(clicks)
    assert not selector.holds_the_scene(clicks[:1]) and carved[c].all() and carved[t].mean() < 0.05
    foot = c[np.argmin(xyz[c, 2])]
    beside = t[np.argsort(np.linalg.norm(xyz[t] - xyz[foot], axis=1))][:5]
    weights = np.zeros(n)
    weights[beside], weights[foot] = 1.0, 0.1
    after = selector.cut([*clicks, ClickEvidence(weights, True)], carved)
    np.testing.assert_array_equal(after, carved)


def test_a_positive_click_on_the_rim_a_large_gaussian_of_the_object_draws_adds_none_of_the_neighbour():
    """The masks hold A (red) and B (blue, touching it) apart; A's outermost Gaussian is ten
    times the median size. A positive click whose pixel that large Gaussian (selected) and
    B's near edge (not) share lands on the selection's rim, although the seeds it pins,
    the large one left out, are B's alone: it adds only seeds of A's colours, none of B."""
    rng = np.random.default_rng(0)
    xyz = np.concatenate([rng.normal(0, 0.3, (200, 3)), rng.normal(0, 0.3, (200, 3)) + [1.2, 0, 0]])
    a, b = np.arange(200), np.arange(200, 400)
    g = _on_a_backdrop(xyz, np.repeat(np.array([[200, 30, 30], [30, 30, 200]]), 200, axis=0))
    n = len(g)
    x = g.means[:, 0].numpy()
    rim = a[np.argmax(x[a])]
    g.log_scales[rim] = g.log_scales.max(1).values.median() + np.log(10.0)
    selector = ClickSelector(g, np.full(n, 7, np.uint8), _regions(n, [a, b]))
    first = _click(n, a[np.argsort(x[a])])
    before = selector.select([first])
    assert before[a].all() and not before[b].any()
    weights = np.zeros(n)
    weights[rim], weights[b[np.argsort(x[b])][:5]] = 1.0, 0.2
    np.testing.assert_array_equal(selector.cut([first, ClickEvidence(weights, True)], before), before)


def test_a_later_positive_click_does_not_pin_a_large_hazy_gaussian():
    """A hazy Gaussian H beside A, drawn in every view over A and over the background alike
    with 20 times A's weight each. Where H is also ten times the median size, a later positive
    click that lands on H alone adds nothing (it would bring the blur H draws beside A); where
    nothing counts as hazy or large, the same click pins H and adds it. Of the median size,
    H is pinned all the same where the click lands on a tenth of its weight in the view: the
    click has no other seed, and an object near the camera is drawn by Gaussians each as
    heavy in the views; not where it lands on a sliver of it (a hundredth)."""
    g, a, b = _two_blobs()
    xyz = np.concatenate([g.means.numpy(), [[0.8, 0.0, 0.0]]])
    rgb = np.concatenate([np.tile([200, 30, 30], (200, 1)), np.tile([30, 30, 200], (200, 1)), [[120, 120, 120]]])
    n, hazy = len(xyz), 400
    regions = _regions(n, [a])
    matrix = regions.matrix.tolil()
    matrix[:, hazy] = 20.0  # in A's region and in the background of every view
    regions = replace(regions, matrix=matrix.tocsr())
    labels = np.zeros(n, np.uint8)
    labels[a] = 1
    first_only = [_click(n, a)]
    for size, options, local, pinned in (
        (10.0, ClickOptions(), None, False),
        (10.0, ClickOptions(off_weight=1e9, large_size=1e9), None, True),
        (1.0, ClickOptions(), None, True),
        (1.0, ClickOptions(), 0.1, True),
        (1.0, ClickOptions(), 0.01, False),
    ):
        on_hazy = ClickEvidence(np.eye(n)[hazy], True, local=None if local is None else np.full(n, local))
        g = gaussians_from_points(xyz, rgb.astype(np.uint8), initial_opacity=0.9)
        g.log_scales[hazy] = g.log_scales.max(1).values.median() + np.log(size)
        selector = ClickSelector(g, labels, regions, options)
        first = selector.select(first_only)
        assert first[a].all() and not first[b].any() and not first[hazy]
        after = selector.cut([*first_only, on_hazy], first)
        assert after[hazy] == pinned and after[a].all() and not after[b].any()


def test_a_later_positive_click_does_not_pin_a_gaussian_many_times_the_median_size():
    """The masks hold the scene, the clicks carve A from B; a later positive click on A's rim
    whose pixel shows only L, a Gaussian ten times the median size drawn behind it, adds
    nothing (L is what stands behind the object, and pinning it would bring what lies near it);
    where no size counts as large, the same click pins L."""
    g, a, b = _two_blobs()
    xyz = np.concatenate([g.means.numpy(), [[1.8, 0.0, 0.0]]])
    rgb = np.concatenate([np.tile([200, 30, 30], (200, 1)), np.tile([30, 30, 200], (200, 1)), [[120, 120, 120]]])
    g = gaussians_from_points(xyz, rgb.astype(np.uint8), initial_opacity=0.9)
    n, large = len(g), 400
    g.log_scales[large] = g.log_scales.max(1).values.median() + np.log(10.0)
    regions = _regions(n, [np.arange(n)])
    clicks = [_click(n, a), _click(n, b, positive=False)]
    on_large = ClickEvidence(np.eye(n)[large], True)
    for options, pinned in ((ClickOptions(), False), (ClickOptions(large_size=1e9), True)):
        selector = ClickSelector(g, np.full(n, 7, np.uint8), regions, options)
        carved = selector.select(clicks)
        assert carved[a].all() and not carved[b].any() and not carved[large]
        after = selector.cut([*clicks, on_large], carved)
        assert after[large] == pinned and after[a].all() and not after[b].any()


def test_a_click_on_the_objects_edge_does_not_bring_the_neighbour_its_pixels_fall_in():
    """A's edge E (20 of its Gaussians) lies under A's mask in one view and under B's in the
    other five (masks that miss a boundary: a statue's shoulder beside a bush), and the
    selection holds A without E. A later click on E, which the vote gives A in part (one
    sixth), speaks through its seeds and the cut, not the regions under it, which in five
    views are B's: nothing of B comes in. A click on B, which the vote holds off A, still
    brings B's regions into the vote."""
    g, a, b = _two_blobs()
    n, edge = len(g), a[:20]
    regions = _views_split([a, b], 1, [np.setdiff1d(a, edge), np.concatenate([b, edge])], 5, n)
    selector = ClickSelector(g, np.full(n, 7, np.uint8), regions)
    first = _click(n, a[50:])
    share, _, _ = selector.views_vote([first], None)
    assert np.allclose(share[edge], 1 / 6) and np.allclose(share[b], 0)
    before = np.zeros(n, bool)
    before[a[20:]] = True
    on_edge = [first, _click(n, edge)]
    share, _, _ = selector.views_vote(on_edge, before)
    assert np.allclose(share[b], 0)
    assert not selector.cut(on_edge, before)[b].any()
    share, _, _ = selector.views_vote([first, _click(n, b)], before)
    assert (share[b] > 0.5).all()


def test_a_part_raises_the_views_vote_and_lowers_it_nowhere():
    """Three views show A alone as an object (B under the background), three show B alone (A
    under the background): the first click on A is seen in the first three, and A's share is
    1. A positive click on B brings in B's regions, and so the last three views, where A falls
    in the background: A's share stays 1 (counted over all six views it would fall to one
    half) and B's rises from 0 to one half."""
    g, a, b = _two_blobs()
    n = len(g)
    regions = _views_split([a], 3, [b], 3, n)
    selector = ClickSelector(g, np.full(n, 7, np.uint8), regions)
    first = selector.select([_click(n, a)])
    share, _, _ = selector.views_vote([_click(n, a)], None)
    assert np.allclose(share[a], 1) and np.allclose(share[b], 0)
    share, seen, _ = selector.views_vote([_click(n, a), _click(n, b)], first)
    assert np.allclose(share[a], 1) and np.allclose(share[b], 0.5) and seen.all()
    both = RegionVote(regions).vote(
        selector.vote.clicked_regions(_click(n, a), 0.2) | (regions.label == 1) & (regions.view >= 3),
        ClickOptions(),
    )[0]
    assert np.allclose(both[a], 0.5)


def test_a_label_over_most_of_every_view_is_the_scene():
    """Six views, each of 400 Gaussians of weight 1: label 1 on 300 of them, label 2 on 100.
    Label 1 holds three quarters of every view: the scene; label 2 is an object in it. With
    label 1 on three eighths of every view and label 2 on the rest, label 2 is the scene."""
    n = 400
    regions = _regions(n, [np.arange(300), np.arange(300, 400)])
    assert regions.covering() == {1}
    assert _regions(n, [np.arange(150), np.arange(150, 400)]).covering() == {2}


def test_the_framed_object_is_the_one_the_views_centre_on_not_the_largest():
    """Six views of 400 Gaussians of weight 1 from a camera at the origin looking along +z:
    object 1 (100 Gaussians) at the view's centre, object 2 (300) at its edge. The photos
    frame object 1 although object 2 holds three times its weight; moved to the centre
    and object 1 to the edge, object 2 is framed."""
    n = 400
    one, two = np.arange(100), np.arange(100, 400)
    regions = _regions(n, [one, two])
    camera = PinholeCamera(100, 100, 50.0, 50.0, 50.0, 50.0)
    views = [CameraPose(camera, np.hstack([np.eye(3), np.zeros((3, 1))]))] * 6
    means = np.zeros((n, 3))
    means[:, 2] = 5.0
    means[two, 0] = 4.5  # projects 45 px right of the centre, at the view's edge
    selections = {1: np.isin(np.arange(n), one), 2: np.isin(np.arange(n), two)}
    assert framed_object(means, selections, regions, views) == 1
    means[:, 0] = 4.5 - means[:, 0]
    assert framed_object(means, selections, regions, views) == 2
    assert framed_object(means, selections, regions, views, least_shown=0.5) == 2  # 1 holds a quarter
    assert framed_object(means, selections, regions, views, least_shown=0.8) is None
    assert framed_object(means, {}, regions, views) is None
    assert np.allclose(regions.view_weights().toarray(), 1.0)


def test_a_mask_pass_that_lost_the_object_does_not_vote_against_it():
    """Two mask layers: three views of the first hold A as an object; four of the second
    leave A in the background but for a sliver (A's first Gaussian, one of the twenty the
    click falls on, and ten more). The second layer holds a twentieth of the click: it does
    not vote, and the sliver, a twentieth of A's weight in its views, joins no round, so A's
    share is 1. Let every layer and region vote and A beyond the sliver falls to three views
    of seven; with the second layer alone, no pass holds more, and it votes."""
    g, a, b = _two_blobs()
    n = len(g)
    sliver = np.r_[a[0], a[190:]]
    click = ClickEvidence(np.isin(np.arange(n), a[:20]).astype(float), True)
    held, lost = _regions(n, [a, b], views=3), _regions(n, [sliver, b], views=4)
    regions = RegionWeights(
        sp.vstack([held.matrix, lost.matrix]).tocsr(),
        np.concatenate([held.view, lost.view]),
        np.concatenate([held.label, lost.label]),
        np.r_[np.zeros(len(held.view), np.uint8), np.ones(len(lost.view), np.uint8)],
        ("depth", "colour"),
    )
    labels = np.full(n, 7, np.uint8)
    share, _, _ = ClickSelector(g, labels, regions).views_vote([click], None)
    assert np.allclose(share[a], 1) and np.allclose(share[b], 0)
    selected = ClickSelector(g, labels, regions).select([click])
    assert selected[a].all() and not selected[b].any()
    everyone = ClickSelector(g, labels, regions, ClickOptions(hold_share=0.01))
    share, _, _ = everyone.views_vote([click], None)
    assert np.allclose(share[a[1:190]], 3 / 7) and np.allclose(share[sliver], 1)
    alone, _, _ = ClickSelector(g, labels, lost).views_vote([click], None)  # no pass holds more: it votes
    assert np.allclose(alone[sliver], 1)


def test_a_negative_click_on_a_floater_leaves_the_objects_side_of_its_own_colour():
    """A red object A (x from 0 to 4) and a green floater F beside its far end, which every
    view's masks join to A: a negative click on F takes F; A's far end, nearer F than the
    positive click along the graph and held by the views as firmly as F, stays because it
    looks like the selection and not like F. Without the colour's word (``against_colour``
    so large that every colour is alike) the far end goes with F."""
    rng = np.random.default_rng(1)
    xyz = np.concatenate(
        [rng.uniform([0, -0.2, -0.2], [4, 0.2, 0.2], (400, 3)), rng.normal([4.6, 0, 0], 0.15, (60, 3))]
    )
    rgb = np.concatenate([np.tile([200, 60, 60], (400, 1)), np.tile([60, 170, 60], (60, 1))])
    rgb = (rgb + rng.uniform(-40, 40, rgb.shape)).astype(np.uint8)  # a trained model's colours vary
    g = _on_a_backdrop(xyz, rgb)
    n, a, f = len(g), np.arange(400), np.arange(400, 460)
    far_end = a[np.argsort(xyz[a, 0])[-80:]]
    near_end = a[np.argsort(xyz[a, 0])[:5]]
    regions, labels = _regions(n, [np.concatenate([a, f])]), np.full(n, 7, np.uint8)
    clicks = [_click(n, near_end), _click(n, f, positive=False)]
    after = ClickSelector(g, labels, regions).select(clicks)
    assert after[f].mean() < 0.2 and after[a].all()
    blind = ClickSelector(g, labels, regions, ClickOptions(against_colour=1e6)).select(clicks)
    assert blind[f].mean() < 0.2 and blind[far_end].mean() < 0.5


# --- the rule on a trained run, through gsseg edit, export and the viewer ----------------------


def _clickable(run, labels: np.ndarray, objects: list[int]) -> dict[int, tuple[str, float, float]]:
    """For each object, the click a user would make on it (:func:`object_click`): a training
    view and the pixel deepest inside it there."""
    views = run.scene().split("train")
    clicks = {obj: object_click(run.gaussians, labels == obj, views) for obj in objects}
    assert all(c is not None for c in clicks.values())
    return {obj: (run.scene().view(c.view).stem, c.u, c.v) for obj, c in clicks.items()}


def _edit(run_dir: Path, *args: str) -> np.ndarray:
    """The Gaussians ``gsseg edit RUN --op extract ARGS`` keeps, (N,) bool over the run's (the
    selection with what served it alone)."""
    r = subprocess.run(
        [script("gsseg"), "edit", str(run_dir), "--op", "extract", "--backend", "cpu", *args],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 0, r.stderr
    return _kept(load_run(run_dir), Path(r.stdout.split()[-1]) / "gaussians.ply")


def _kept(run, ply: Path) -> np.ndarray:
    kept = {tuple(p) for p in read_ply(ply).means.numpy().tolist()}
    return np.array([tuple(p) in kept for p in run.gaussians.means.numpy().tolist()])


def _iou(x: np.ndarray, y: np.ndarray, weight: np.ndarray) -> float:
    """IoU of two selections, each Gaussian counted by ``weight`` (its opacity: a Gaussian
    nearly transparent changes no picture, wherever it goes)."""
    return float(weight[x & y].sum() / max(weight[x | y].sum(), 1e-12))


def _joined_labels(segmented: Path, tmp_path: Path):
    """A copy of the test run whose two largest objects a and b share a's label in labels.npz
    (the masks still tell them apart): (run folder, run, its own labels, a, b)."""
    run_dir = Path(shutil.copytree(segmented, tmp_path / "run"))
    run = load_run(run_dir)
    seg = run.labels()
    counts = np.bincount(seg.labels, minlength=256)
    a, b = (int(o) for o in np.argsort(-counts[1:])[:2] + 1)
    merged = np.where(seg.labels == b, a, seg.labels).astype(np.uint8)
    objects = np.array([o for o in seg.objects if o != b], np.uint8)
    run.folder.write_labels(seg.relabelled(merged, objects=objects))
    return run_dir, run, seg, a, b


@pytest.mark.slow
def test_clicks_carve_objects_the_labels_joined(segmented, small_scene, tmp_path):
    """The test run's two largest objects a and b given one label (as the weight-free masks
    join an object to what it stands on): a click on a selects a (the views hold it apart);
    where the masks join them as well, one click selects both and an excluding click on b
    takes out part of what its view shows of b (on this rough 200-step model a quarter to
    most of it, by the rounding of the library versions that trained it), keeping a
    (Gaussians counted by opacity: the colour model also takes a's nearly transparent haze,
    which the labels leave out). ``gsseg export`` selects what ``gsseg edit`` selects."""
    run_dir, run, seg, a, b = _joined_labels(segmented, tmp_path)
    clicks = _clickable(run, seg.labels, [a, b])
    at_a = ["--click", *map(str, clicks[a])]
    own_a, own_b = seg.labels == a, seg.labels == b
    opacity = run.gaussians.opacities.detach().numpy()

    alone = _edit(run_dir, *at_a, "--name", "a")
    assert _iou(alone, own_a, opacity) > 0.9

    # masks that join a and b in every view: the views no longer hold them apart
    scene = Path(shutil.copytree(small_scene.root, tmp_path / "scene"))
    for view in load_scene(scene, masks="object_mask").views:
        mask = view.load_mask()
        write_bytes_atomic(view.mask_path, encode_png(np.where(mask == b, a, mask).astype(np.uint8)))
    segment_run(run_dir, scene, backend="cpu", progress=False)
    run = load_run(run_dir)
    scene_args = ["--scene", str(scene)]
    joined = _edit(run_dir, *at_a, *scene_args, "--name", "joined")
    assert _iou(joined, own_a | own_b, opacity) > 0.9
    split = _edit(run_dir, *at_a, "--exclude-click", *map(str, clicks[b]), *scene_args, "--name", "split")
    view_b = run.scene().view(clicks[b][0])
    shown = click_evidence(run.gaussians, view_b.camera, view_b.cam_from_world, *clicks[b][1:]).shown
    shown_b = own_b & (shown >= ClickOptions().shown_share)
    assert (split & own_a).sum() >= 0.98 * (joined & own_a).sum()
    assert (split & shown_b).sum() < 0.8 * (joined & shown_b).sum() and (split & own_b).sum() < (joined & own_b).sum()
    record = json.loads((run_dir / "edits" / "split" / "edit.json").read_text())
    assert [c["positive"] for c in record["clicks"]] == [True, False] and record["object_id"] is None
    exported = tmp_path / "split.ply"
    r = subprocess.run(
        [
            script("gsseg"),
            "export",
            str(run_dir),
            "--out",
            str(exported),
            *at_a,
            "--exclude-click",
            *map(str, clicks[b]),
        ]
        + scene_args,
        capture_output=True,
        text=True,
    )
    assert r.returncode == 0, r.stderr
    np.testing.assert_array_equal(_kept(run, exported), split)


@pytest.mark.slow
def test_the_viewers_clicks_select_what_gsseg_edit_selects(segmented, tmp_path):
    """The viewer's click, ctrl-click and shift-click select what ``gsseg edit --click`` and
    ``--exclude-click`` select; a removal keeps the rest; undo restores."""
    from gsseg.viewer.session import ViewCamera, ViewerSession

    run_dir, run, seg, a, b = _joined_labels(segmented, tmp_path)
    clicks = _clickable(run, seg.labels, [a, b])
    session = ViewerSession(load_run(run_dir), backend="cpu")
    scene = run.scene()

    def at(obj: int, mode: str) -> np.ndarray:
        """The viewer's selection after a click on ``obj``, as an extraction takes it."""
        view = scene.view(clicks[obj][0])
        chosen = session.select_at(ViewCamera(view.camera, view.cam_from_world), clicks[obj][1], clicks[obj][2], mode)
        return complete_selection(run.gaussians, chosen, scene.split("train")).mask

    with pytest.raises(InputError, match="click an object first"):
        at(b, "exclude")
    np.testing.assert_array_equal(at(a, "select"), _edit(run_dir, "--click", *map(str, clicks[a]), "--name", "1"))
    added = at(b, "add")
    np.testing.assert_array_equal(
        added, _edit(run_dir, "--click", *map(str, clicks[a]), "--click", *map(str, clicks[b]), "--name", "2")
    )
    at(a, "select")
    taken = at(b, "exclude")
    expected = _edit(run_dir, "--click", *map(str, clicks[a]), "--exclude-click", *map(str, clicks[b]), "--name", "3")
    np.testing.assert_array_equal(taken, expected)
    session.edit("remove")
    assert len(session.current()[0]) == len(run.gaussians) - expected.sum() and session.selection() is None
    assert session.undo().object_id is None and len(session.current()[0]) == len(run.gaussians)


@pytest.mark.slow
def test_a_click_where_the_masks_hold_the_scene_says_so(segmented, small_scene, tmp_path):
    """Masks of one region over every view (weight-free masks that read a plant and the room
    behind it as one): a click on an object is cut from its view's frame, most of the object
    and little of the rest, and ``gsseg edit``'s selection and the viewer say that the clicks
    decide where it ends. With the run's own masks, or once a click is against, they say
    nothing."""
    from gsseg.edits import select
    from gsseg.viewer.session import ViewCamera, ViewerSession

    run = load_run(segmented)
    seg = run.labels()
    a, b = (int(o) for o in np.argsort(-np.bincount(seg.labels, minlength=256)[1:])[:2] + 1)
    on_object = seg.labels == a
    on_a, on_b = (object_click(run.gaussians, seg.labels == o, run.scene().split("train")) for o in (a, b))
    with warnings.catch_warnings():
        warnings.simplefilter("error", SceneHeld)
        select(run, seg, run.scene(small_scene.root), clicks=[on_a], backend="cpu")

    run_dir = Path(shutil.copytree(segmented, tmp_path / "run"))
    one = Path(shutil.copytree(small_scene.root, tmp_path / "scene"))
    for view in load_scene(one, masks="object_mask").views:
        write_bytes_atomic(view.mask_path, encode_png(np.ones_like(view.load_mask())))
    segment_run(run_dir, one, backend="cpu", progress=False)
    run = load_run(run_dir)
    seg, scene = run.labels(), run.scene(one)
    with pytest.warns(SceneHeld, match="exclude-click"):
        framed = select(run, seg, scene, clicks=[on_a], backend="cpu").mask
    assert (framed & on_object).sum() > 0.5 * on_object.sum() and (framed & ~on_object).sum() < on_object.sum()
    with warnings.catch_warnings():
        warnings.simplefilter("error", SceneHeld)
        select(run, seg, scene, clicks=[on_a, replace(on_b, positive=False)], backend="cpu")
    session = ViewerSession(run, scene_dir=one, backend="cpu")
    for click, mode, held in ((on_a, "select", True), (on_b, "exclude", False)):
        view = scene.view(click.view)
        session.select_at(ViewCamera(view.camera, view.cam_from_world), click.u, click.v, mode)
        assert session.scene_held() is held
