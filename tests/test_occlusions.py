"""Masks cut where the depth jumps (``hqmask/occlusions.py``, ``hqmask build --depth``): known
answers on drawn images, the depth maps' round trip and their errors, and a build that uses the
exact depth of a synthetic scene."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from dataset_tools import InputError, load_scene
from dataset_tools.depth_maps import read_depth, write_depth
from dataset_tools.synth.generator import render_view
from hqmask.build import CACHE, BuildConfig, build_masks
from hqmask.occlusions import cut_at_edges, depth_jumps
from hqmask.proposers.graph import GraphProposer
from hqmask.support_plane import Heights


def test_a_step_in_depth_is_an_edge_and_a_tilted_plane_is_not():
    rows = np.linspace(1.0, 3.0, 64)[:, None] * np.ones((1, 64))  # a floor seen at a slant: depth x3 over 64 rows
    assert not depth_jumps(rows.astype(np.float32), 0.2).edges.any()
    step = np.ones((64, 64), np.float32)
    step[:, 32:] = 1.5  # a 50% jump between columns 31 and 32
    edges = depth_jumps(step, 0.2).edges
    assert edges[:, 31:33].all() and not edges[:, :31].any() and not edges[:, 33:].any()
    sky = np.ones((64, 64), np.float32)
    sky[:, 40:] = 0  # nothing opaque: beyond everything
    assert depth_jumps(sky, 0.2).edges[:, 39:41].all()


def test_cut_at_edges_splits_only_the_region_that_spans_a_jump():
    seg = np.zeros((40, 60), np.int64)
    seg[:, 30:] = 1
    edges = np.zeros_like(seg, bool)
    edges[:, 14:16] = True  # crosses region 0 only
    out = cut_at_edges(seg, edges, min_size=20)
    assert len(np.unique(out)) == 3
    assert len(np.unique(out[:, :14])) == 1 and len(np.unique(out[:, 16:30])) == 1
    assert out[0, 0] != out[0, 20] and len(np.unique(out[:, 30:])) == 1
    assert (np.unique(out[:, 14:16]) == np.unique(out[:, :16])).all()  # edge pixels join a side
    tiny = np.zeros_like(seg, bool)
    tiny[:, 3:5] = True  # leaves a 3-column sliver of 120 pixels under min_size
    assert len(np.unique(cut_at_edges(seg, tiny, min_size=200))) == 2


def _drawn(shapes: list[tuple[str, tuple, tuple[int, int, int], float]], size: int = 128):
    """An image and its depth: grey floor far behind (depth 5), shapes drawn in order, each
    ("circle", (cx, cy, r) | "rect", (x0, y0, x1, y1), colour, depth)."""
    image = np.full((size, size, 3), 150, np.uint8)
    depth = np.full((size, size), 5.0, np.float32)
    for kind, geometry, colour, z in shapes:
        mask = np.zeros((size, size), np.uint8)
        if kind == "circle":
            cv2.circle(mask, geometry[:2], geometry[2], 1, -1)
        else:
            cv2.rectangle(mask, geometry[:2], geometry[2:], 1, -1)
        image[mask > 0], depth[mask > 0] = colour, z
    return image, depth


def test_one_colour_at_two_depths_is_two_objects():
    dark = (40, 60, 40)
    image, depth = _drawn([("circle", (50, 64, 28), dark, 3.0), ("circle", (80, 64, 26), dark, 1.5)])
    proposer = GraphProposer()
    assert len(proposer.propose(image, None).masks) == 1  # colour alone: one blob
    masks = proposer.propose(image, None, depth).masks
    assert len(masks) == 2
    near = depth == 1.5
    ious = [(m & near).sum() / (m | near).sum() for m in masks]
    assert max(ious) > 0.9


def test_a_part_that_only_depth_jumps_outline_joins_the_object_it_sits_on():
    image, depth = _drawn(
        [
            ("rect", (0, 101, 127, 127), (150, 150, 150), 2.0),  # the floor it stands on
            ("rect", (40, 60, 88, 100), (40, 40, 160), 2.0),  # a blue torso
            ("circle", (64, 48, 16), (190, 150, 60), 2.0),
        ]
    )  # an ochre head on it
    proposer = GraphProposer()
    assert len(proposer.propose(image, None).masks) == 2  # hues 100 degrees apart
    masks = proposer.propose(image, None, depth).masks
    assert len(masks) == 1 and masks[0][48, 64] and masks[0][80, 64]


def test_depth_maps_round_trip_and_are_checked(tmp_path):
    depth = np.random.default_rng(0).uniform(0, 4, (6, 8)).astype(np.float32)
    write_depth(tmp_path / "a.npy", depth)
    assert np.array_equal(read_depth(tmp_path / "a.npy", (8, 6)), depth)
    with pytest.raises(InputError, match=r"a\.npy.*view is 6x8"):
        read_depth(tmp_path / "a.npy", (6, 8))
    with pytest.raises(InputError, match=r"b\.npy: depth map not found"):
        read_depth(tmp_path / "b.npy", (8, 6))
    (tmp_path / "c.npy").write_bytes(b"not numpy")
    with pytest.raises(InputError, match=r"c\.npy: not a depth map"):
        read_depth(tmp_path / "c.npy", (8, 6))
    write_depth(tmp_path / "d.npy", -depth)
    with pytest.raises(InputError, match="negative"):
        read_depth(tmp_path / "d.npy", (8, 6))


def _exact_depths(small_scene, folder):
    """The generator's exact depth of every view of ``small_scene``, as ``render --what depth``
    writes it (0 for the sky)."""
    for view in load_scene(small_scene.root, masks=None).views:
        _, _, depth, _ = render_view(small_scene.layout, view.camera, view.cam_from_world, 1)
        write_depth(folder / f"{view.stem}.npy", np.where(np.isfinite(depth), depth, 0.0))
    return folder


def test_a_build_with_depth_keeps_the_objects_and_caches_apart(small_scene, scene_copy, tmp_path):
    depth = _exact_depths(small_scene, tmp_path / "depth")
    plain = build_masks(scene_copy, BuildConfig(out_masks="plain"), progress=False)
    cut = build_masks(scene_copy, BuildConfig(out_masks="cut", depth=str(depth)), progress=False)
    assert plain.n_objects >= 1 and cut.n_objects >= 1
    cached = sorted(p.name for p in (scene_copy / CACHE).iterdir())
    assert cached[0] == "graph" and cached[1].startswith("graph-depth-") and len(cached) == 2
    plain_cover, cut_cover = _covered(small_scene, scene_copy, "plain"), _covered(small_scene, scene_copy, "cut")
    assert cut_cover.mean() >= plain_cover.mean() - 0.01  # measured: 0.950 against 0.918
    assert cut_cover.min() >= 0.6  # measured: 0.75 against 0.41


def _covered(small_scene, scene_dir, masks) -> np.ndarray:
    """For every object of over 100 px in every view, the share of it that its best mask ID covers."""
    covered = []
    for truth, built in zip(load_scene(small_scene.root).views, load_scene(scene_dir, masks=masks).views):
        gt, ids = truth.load_mask(), built.load_mask()
        for obj in np.unique(gt[gt > 0]):
            if (gt == obj).sum() > 100:
                inside = ids[gt == obj]
                covered.append(np.bincount(inside[inside > 0], minlength=256).max() / len(inside))
    return np.array(covered)


def test_a_depth_map_of_the_wrong_size_is_refused_naming_it(small_scene, scene_copy, tmp_path):
    depth = _exact_depths(small_scene, tmp_path / "depth")
    first = sorted(depth.glob("*.npy"))[0]
    write_depth(first, np.ones((5, 5), np.float32))
    with pytest.raises(InputError, match=rf"{first.name}: a map of shape \(5, 5\)"):
        build_masks(scene_copy, BuildConfig(out_masks="cut", depth=str(depth)), progress=False)
    assert not (scene_copy / "cut").exists()
    np.save(first, np.ones((96, 96), np.int64))  # the right size, but no depths
    with pytest.raises(InputError, match=rf"{first.name}: a map of int64, not of floating-point depths"):
        build_masks(scene_copy, BuildConfig(out_masks="cut", depth=str(depth)), progress=False)
    with pytest.raises(InputError, match="only the graph proposer"):
        build_masks(
            scene_copy,
            BuildConfig(out_masks="cut", proposer="existing", from_masks="object_mask", depth=str(depth)),
            progress=False,
        )
    with pytest.raises(InputError, match="depth folder not found"):
        build_masks(scene_copy, BuildConfig(out_masks="cut", depth=str(tmp_path / "none")), progress=False)


def test_the_rendered_depth_of_a_run_is_the_scenes(trained, small_scene, tmp_path):
    """``gsseg render --what depth`` of the 200-iteration test run against the generator's
    exact depth: the median relative error where both see a surface."""
    from gsseg.render.views import render_run

    out = render_run(
        trained, small_scene.root, tmp_path / "r", split="all", what=("depth",), backend="cpu", progress=False
    )
    errors = []
    for view in load_scene(small_scene.root, masks=None).views:
        rendered = read_depth(out / "depth" / f"{view.stem}.npy", (view.camera.width, view.camera.height))
        _, _, exact, _ = render_view(small_scene.layout, view.camera, view.cam_from_world, 1)
        both = (rendered > 0) & np.isfinite(exact)
        assert both.mean() > 0.5
        errors.append(np.median(np.abs(rendered[both] - exact[both]) / exact[both]))
    assert np.median(errors) < 0.1  # measured: 0.059


def test_voting_with_masks_the_run_was_not_trained_on_leaves_the_prior_out(segmented, small_scene, tmp_path):
    import shutil

    from gsseg.segment.label_options import LabelOptions
    from gsseg.segment.segment_run import segment_run

    run = tmp_path / "run"
    shutil.copytree(segmented, run)
    scene = tmp_path / "scene"
    shutil.copytree(small_scene.root, scene)
    shutil.copytree(scene / "object_mask", scene / "rebuilt")
    same = segment_run(run, scene, options=LabelOptions(gamma_p=0.2), backend="cpu", progress=False)
    other = segment_run(run, scene, options=LabelOptions(gamma_p=0.2), masks="rebuilt", backend="cpu", progress=False)
    assert same.gamma_p == 0.2 and other.gamma_p == 0.0


def test_what_stands_in_front_is_an_object_whatever_its_colour():
    floor = (150, 150, 150)
    image, depth = _drawn([("circle", (64, 64, 24), floor, 1.0)])  # the floor's colour, 5x nearer
    proposer = GraphProposer()
    assert len(proposer.propose(image, None).masks) == 0  # colour alone: one more floor tile
    masks = proposer.propose(image, None, depth).masks
    assert len(masks) == 1 and masks[0][64, 64] and not masks[0][5, 5]


def test_the_support_plane_of_a_synthetic_scene_is_its_floor(small_scene, tmp_path):
    from hqmask.build import read_geometry

    scene = load_scene(small_scene.root)
    geometry = read_geometry(scene, _exact_depths(small_scene, tmp_path / "depth"))
    assert geometry.plane is not None and geometry.plane.normal @ np.array([0.0, 0.0, 1.0]) > 0.99
    floor = np.concatenate(
        [h[(v.load_mask() == 0) & np.isfinite(h)] for v, h in zip(scene.views, [h.values for h in geometry.heights])]
    )
    objects = np.concatenate([h[v.load_mask() > 0] for v, h in zip(scene.views, [h.values for h in geometry.heights])])
    assert np.percentile(np.abs(floor), 99) < 0.01  # measured: 0.000
    assert np.median(objects) > 0.2  # measured: 0.30 (in units of the points' spread)


def test_what_rises_from_the_floor_is_an_object_even_at_the_border():
    image, depth = _drawn([("rect", (0, 30, 50, 100), (170, 60, 50), 3.0)])  # a red model cut by the frame
    height = np.where(image[..., 0] == 170, 0.6, 0.0).astype(np.float32)  # the floor at 0
    proposer = GraphProposer()
    assert len(proposer.propose(image, None, depth).masks) == 0  # it touches the border
    masks = proposer.propose(image, None, depth, Heights(height, contact=False)).masks
    assert len(masks) == 1 and masks[0][60, 10] and not masks[0][60, 100]


def test_in_an_orbit_only_what_the_points_see_rises():
    """A red model cut by the frame and a green table beside it, both rising in the run's
    depth; the view's SfM points lie on the model alone (the table is a surface they never
    saw, as the still room around a turntable). Under a plane found elsewhere both stand;
    under an orbit's focus the table, with no point, is background; without any point in the
    view the rule says nothing."""
    image, depth = _drawn(
        [("rect", (0, 30, 50, 100), (170, 60, 50), 3.0), ("rect", (70, 0, 127, 127), (40, 140, 40), 3.0)]
    )
    height = np.where((image[..., 0] == 170) | (image[..., 1] == 140), 0.6, 0.0).astype(np.float32)
    observed = np.zeros(height.shape, bool)
    observed[35:95:4, 5:45:4] = True  # on the model
    proposer = GraphProposer()
    assert len(proposer.propose(image, None, depth, Heights(height, False, observed)).masks) == 2
    masks = proposer.propose(image, None, depth, Heights(height, True, observed)).masks
    assert len(masks) == 1 and masks[0][60, 20] and not masks[0][60, 100]
    none = np.zeros_like(observed)
    assert len(proposer.propose(image, None, depth, Heights(height, True, none)).masks) == 2


def test_an_object_of_its_supports_colour_comes_apart_where_it_rises():
    """A grey model on a grey floor, at the floor's depth where it stands (no jump): colour
    and depth see one region touching the border, all background, and so do the heights
    without the cut at the contact (a plane not under an orbit's focus); with it the region is
    cut where it rises past ``contact_height`` and the model stands: an object, the floor
    around it not."""
    image, depth = _drawn([])
    height = np.zeros(depth.shape, np.float32)
    height[30:101, 0:51] = np.linspace(0.0, 0.6, 71, dtype=np.float32)[::-1, None]  # rising from its foot
    proposer = GraphProposer()
    assert len(proposer.propose(image, None, depth).masks) == 0
    assert len(proposer.propose(image, None, depth, Heights(height, contact=False)).masks) == 0
    masks = proposer.propose(image, None, depth, Heights(height, contact=True)).masks
    rises = height >= proposer.contact_height
    assert len(masks) == 1 and (masks[0] & rises).sum() / (masks[0] | rises).sum() > 0.95


def test_what_rises_far_behind_the_scene_stays_background():
    """A backdrop (height -inf: beyond the scene's reach) touching the frame beside a model that
    rises from the floor: the model is an object, the backdrop is not."""
    image, depth = _drawn(
        [("rect", (0, 0, 127, 40), (20, 20, 25), 9.0), ("rect", (0, 60, 50, 127), (170, 60, 50), 3.0)]
    )
    height = np.zeros(depth.shape, np.float32)
    height[image[..., 0] == 170] = 0.6
    height[image[..., 0] == 20] = -np.inf
    masks = GraphProposer().propose(image, None, depth, Heights(height, contact=False)).masks
    assert len(masks) == 1 and masks[0][90, 10] and not masks[0][20, 60]
    height[image[..., 0] == 20] = 2.0  # the same backdrop within reach rises like the model
    assert len(GraphProposer().propose(image, None, depth, Heights(height, contact=False)).masks) == 2


def test_in_an_orbit_what_lies_beyond_the_cameras_is_no_object():
    """A red model standing on the floor and a green bush seen over the floor beyond the
    plane's reach (height -inf), neither touching the frame: under a plane found elsewhere the
    bush is an object, under an orbit's focus (the reach is the cameras' ring: the bush grows
    behind them) it is background."""
    image, depth = _drawn(
        [("circle", (90, 40, 15), (40, 140, 40), 9.0), ("rect", (20, 60, 60, 110), (170, 60, 50), 3.0)]
    )
    height = np.zeros(depth.shape, np.float32)
    height[image[..., 0] == 170] = 0.6
    height[image[..., 1] == 140] = -np.inf
    proposer = GraphProposer()
    assert len(proposer.propose(image, None, depth, Heights(height, contact=False)).masks) == 2
    masks = proposer.propose(image, None, depth, Heights(height, contact=True)).masks
    assert len(masks) == 1 and masks[0][80, 40] and not masks[0][40, 90]


def _looking_at(centre: np.ndarray, target: np.ndarray) -> np.ndarray:
    """(3, 4) cam_from_world of an upright camera (world z up) at ``centre`` looking at ``target``."""
    forward = (target - centre) / np.linalg.norm(target - centre)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    R = np.stack([right, np.cross(forward, right), forward])  # rows: x right, y down, z forward
    return np.concatenate([R, (-R @ centre)[:, None]], 1)


def test_in_an_orbit_the_support_is_the_surface_under_the_focus():
    """A slab (top at z = 0.5, radius 1) on a wide ground (z = 0) holding more points than the
    slab, an object on the slab, twelve cameras in a ring of radius 4 looking at it. In the
    orbit the support is the slab's top, whatever lies under it, and the reach ends at the
    ring; the same points seen from one side (no orbit) stand on the ground, which has
    nothing under it."""
    from hqmask.support_plane import orbit_of, support_plane

    rng = np.random.default_rng(0)
    ground = np.c_[rng.uniform(-6, 6, (3000, 2)), np.zeros(3000)]
    ground = ground[np.linalg.norm(ground[:, :2], axis=1) > 1.2]
    radius, angle = np.sqrt(rng.uniform(0, 1, 600)), rng.uniform(0, 2 * np.pi, 600)
    slab = np.c_[radius * np.cos(angle), radius * np.sin(angle), np.full(600, 0.5)]
    model = rng.normal([0, 0, 0.9], 0.2, (400, 3))
    points = np.concatenate([ground, slab, model])
    target = np.array([0.0, 0.0, 0.8])
    ring = [
        _looking_at(np.array([4 * np.cos(a), 4 * np.sin(a), 2.0]), target) for a in np.linspace(0, 2 * np.pi, 13)[:-1]
    ]
    orbit = orbit_of(np.array(ring))
    assert orbit is not None and np.allclose(orbit.focus, target, atol=1e-6) and orbit.up @ [0, 0, 1] > 0.99
    plane = support_plane(points, np.array(ring))
    assert plane.under_focus and plane.normal @ [0, 0, 1] > 0.99 and plane.offset == pytest.approx(-0.5, abs=0.02)
    assert plane.reach * plane.scale == pytest.approx(4.0, rel=1e-6)
    side = [_looking_at(np.array([x, -4.0, 2.0]), target) for x in np.linspace(-1, 1, 5)]
    assert orbit_of(np.array(side)) is None
    plane = support_plane(points, np.array(side))
    assert not plane.under_focus and plane.normal @ [0, 0, 1] > 0.99 and plane.offset == pytest.approx(0.0, abs=0.02)


def test_heights_beyond_the_reach_of_the_scene_are_minus_infinity():
    """A camera 4 units above the floor z = 0 looking straight down at the scene's centre: the
    floor under it is at height 0, a floor point farther than ``reach`` scales along the plane
    is -inf, a pixel where nothing is opaque is NaN."""
    from types import SimpleNamespace

    from dataset_tools.cameras import PinholeCamera
    from hqmask.support_plane import SupportPlane

    plane = SupportPlane(np.array([0.0, 0.0, 1.0]), 0.0, scale=1.0, centre=np.zeros(3), reach=3.0)
    camera = PinholeCamera(64, 64, 8.0, 8.0, 32.0, 32.0)  # a pixel spans half a unit of floor at depth 4
    down = np.array([[1.0, 0, 0, 0], [0, -1, 0, 0], [0, 0, -1, 4.0]])  # camera at z = 4, looking along -z
    depth = np.full((64, 64), 4.0, np.float32)
    depth[0, 0] = 0.0
    heights = plane.heights(SimpleNamespace(camera=camera, cam_from_world=down, uv=np.zeros((0, 2))), depth).values
    assert heights[32, 32] == pytest.approx(0.0, abs=1e-5) and heights[32, 37] == pytest.approx(0.0, abs=1e-5)
    assert np.isneginf(heights[32, 38]) and np.isneginf(heights[5, 5]) and np.isnan(heights[0, 0])  # 3.26 units out
    assert np.isfinite(heights[32, 26]) and np.isneginf(heights[32, 25])  # 2.76 and 3.26 units out


def test_colour_merge_is_scikit_images_region_adjacency_cut(small_scene):
    """:func:`merge_by_mean_colour` against scikit-image's ``rag_mean_color`` +
    ``cut_threshold`` (the reference) on Felzenszwalb regions of two rendered views and of
    a random label map: the same region map, label for label."""
    from skimage import color, graph, segmentation

    from hqmask.proposers.graph import merge_by_mean_colour

    rng = np.random.default_rng(0)
    cases = []
    for view in load_scene(small_scene.root).views[:2]:
        image = view.load_image()
        cases.append((segmentation.felzenszwalb(image, scale=100, sigma=0.8, min_size=20), color.rgb2lab(image)))
    cases.append((rng.integers(0, 40, (30, 24)), rng.normal(0, 10, (30, 24, 3))))
    for seg, lab in cases:
        for threshold in (4.0, 8.0, 16.0):
            expected = graph.cut_threshold(seg, graph.rag_mean_color(lab, seg), threshold)
            np.testing.assert_array_equal(merge_by_mean_colour(seg, lab, threshold), expected)
