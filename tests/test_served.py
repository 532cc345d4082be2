"""What a selection leaves behind (gsseg.segment.served)."""

from __future__ import annotations

import numpy as np
import torch

from dataset_tools.cameras import CameraPose, PinholeCamera
from dataset_tools.synth.camera_paths import look_at
from gsseg.model.gaussians import Gaussians
from gsseg.segment.served import complete_selection


def _blobs(centres: np.ndarray, scale: float, opacity: float, colour: float) -> Gaussians:
    """Round Gaussians at ``centres`` (P, 3), all of one size, opacity and grey."""
    n = len(centres)
    return Gaussians(
        means=torch.as_tensor(centres, dtype=torch.float32),
        log_scales=torch.full((n, 3), float(np.log(scale))),
        quats=torch.tensor([[1.0, 0, 0, 0]]).repeat(n, 1),
        opacity_logits=torch.full((n,), float(np.log(opacity / (1 - opacity)))),
        sh_dc=torch.full((n, 3), colour),
        sh_rest=torch.zeros(n, 15, 3),
        obj_feat=torch.zeros(n, 16),
    )


def _ball(rng: np.random.Generator) -> np.ndarray:
    """400 points on a sphere of radius 0.5 about the origin."""
    ball = rng.normal(size=(400, 3))
    return 0.5 * ball / np.linalg.norm(ball, axis=1, keepdims=True)


def _around_the_top() -> list[CameraPose]:
    """Five 64x64 cameras 4 from the origin, 25 degrees from its top, looking at it."""
    camera = PinholeCamera(64, 64, 60.0, 60.0, 32.0, 32.0)
    tilt = np.radians(25)
    views = []
    for a in np.radians([0, 72, 144, 216, 288]):
        eye = 4.0 * np.array([np.sin(tilt) * np.cos(a), np.sin(tilt) * np.sin(a), np.cos(tilt)])
        views.append(CameraPose(camera, look_at(eye, np.zeros(3))))
    return views


def test_a_haze_over_the_object_goes_with_it_what_stands_before_it_stays():
    """A ball of 400 opaque Gaussians (the selection) seen from five cameras within 25
    degrees of its top, a wall of 400 behind it, and two unselected patches of 40 over the
    ball's top: a faint haze on its surface, which the ball outweighs wherever it shows (it
    served the ball alone, and goes with it), and an opaque patch 0.4 in front of it, which
    wins its own pixels (another thing standing before the ball: it stays, as the wall
    does)."""
    rng = np.random.default_rng(0)
    ball = _ball(rng)
    haze = rng.normal(size=(40, 3)) * [0.07, 0.07, 0.0] + [0.15, 0.0, 0.55]
    front = rng.normal(size=(40, 3)) * [0.03, 0.03, 0.0] + [-0.3, 0.0, 0.9]
    wall = np.c_[rng.uniform(-2, 2, (400, 2)), np.full(400, -1.5)]
    g = Gaussians.concat(
        _blobs(ball, 0.08, 0.99, 0.5),
        _blobs(haze, 0.05, 0.03, 1.5),
        _blobs(front, 0.05, 0.99, 1.5),
        _blobs(wall, 0.15, 0.99, -1.0),
    )
    selected = np.r_[np.ones(400, bool), np.zeros(480, bool)]
    done = complete_selection(g, selected, _around_the_top())
    assert done.mask[400:440].all() and done.added == 40
    assert not done.mask[440:].any()
    assert done.ghost_after < done.ghost_before


def test_what_the_object_hides_from_every_view_goes_with_it():
    """The ball and the wall behind it, and five large Gaussians about the ball's centre: the
    ball hides their centres from every camera, but their tails show around its rim, so
    half their weight falls outside its silhouettes. They go with the ball (what training
    left inside an object, a dark speck at a can's foot once the can is removed). The wall
    stays, also where the ball hides it from every camera: it lies beyond the ball."""
    rng = np.random.default_rng(0)
    inner = rng.normal(size=(5, 3)) * 0.05
    wall = np.c_[rng.uniform(-2, 2, (400, 2)), np.full(400, -1.5)]
    g = Gaussians.concat(
        _blobs(_ball(rng), 0.08, 0.99, 0.5), _blobs(inner, 0.3, 0.99, -1.0), _blobs(wall, 0.15, 0.99, 1.0)
    )
    done = complete_selection(g, np.r_[np.ones(400, bool), np.zeros(405, bool)], _around_the_top())
    assert done.mask[400:405].all() and done.added == 5
    assert not done.mask[405:].any()


def test_within_the_reach_of_the_hull_most_of_the_weight_inside_is_enough():
    """A flat ring of 600 Gaussians (the selection) seen from the five cameras above it, and
    four unselected patches of 8: along its inner edge just under its top (within the hull of
    the ring's centres: its rim, which the vote gave to the hole's floor; most of their weight
    falls inside the ring's silhouettes, none 90% of it, and each wins a few pixels of its
    own), along its outer edge (beyond the hull of the centres, but within the reach of the
    ring's Gaussians: its blurred edge, which the vote gave to the ground around it), under
    its band 0.25 below it (the ground it stands over, beyond the reach of its Gaussians),
    and a patch in the hole (within the hull, but seen through it: its weight falls outside
    the silhouettes). Both rims go with the ring wherever at least half their weight falls
    inside; the ground under it and what shows through the hole stay."""
    rng = np.random.default_rng(0)
    angle, radius = rng.uniform(0, 2 * np.pi, 600), np.sqrt(rng.uniform(0.5**2, 0.8**2, 600))
    ring = np.c_[radius * np.cos(angle), radius * np.sin(angle), rng.uniform(-0.1, 0.1, 600)]
    wall = np.c_[rng.uniform(-2, 2, (400, 2)), np.full(400, -1.5)]
    around = np.radians(np.arange(0, 360, 45))
    inner = np.c_[0.52 * np.cos(around), 0.52 * np.sin(around), np.full(8, 0.09)]
    outer = np.c_[0.8 * np.cos(around), 0.8 * np.sin(around), np.zeros(8)]
    under = np.c_[0.65 * np.cos(around), 0.65 * np.sin(around), np.full(8, -0.35)]
    hole = rng.normal(size=(8, 3)) * [0.05, 0.05, 0.0] + [0, 0, -0.05]
    g = Gaussians.concat(
        _blobs(ring, 0.06, 0.99, 0.5),
        _blobs(inner, 0.08, 0.99, -1.0),
        _blobs(outer, 0.08, 0.99, -1.0),
        _blobs(under, 0.08, 0.99, -1.0),
        _blobs(hole, 0.06, 0.99, -1.0),
        _blobs(wall, 0.15, 0.99, 1.0),
    )
    done = complete_selection(g, np.r_[np.ones(600, bool), np.zeros(432, bool)], _around_the_top())
    assert done.mask[600:608].sum() == 7  # the one with 46% of its weight inside stays
    assert done.mask[608:616].sum() == 7  # as does one on the outer edge
    assert not done.mask[616:].any()
