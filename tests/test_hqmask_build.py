"""hqmask build/clean: association on masks whose IDs are permuted per view, outputs, errors."""

import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import pytest

from dataset_tools import InputError, load_scene
from dataset_tools.corruption import PERMUTE_ONLY, corrupt_mask
from dataset_tools.image_files import write_png
from dataset_tools.label_maps import consistent_fraction, match_ids, overlap
from dataset_tools.scene import GT_MASKS
from dataset_tools.synth import SynthConfig, generate_scene
from hqmask.build import BuildConfig, build_masks, clean_scene_masks, read_cached_segments


def permuted_masks(scene_dir: Path, name: str) -> None:
    scene = load_scene(scene_dir, masks=GT_MASKS)
    for k, v in enumerate(scene.views):
        write_png(
            scene_dir / name / f"{v.stem}.png", corrupt_mask(v.load_mask(), PERMUTE_ONLY, np.random.default_rng(k))
        )


@pytest.mark.parametrize("method, path", [("flow", "forward"), ("tracks", "forward"), ("tracks", "orbit")])
def test_association_undoes_per_view_permutations(tmp_path, method, path):
    """Flow is tested on a forward-facing capture (small motion between views), what it is for."""
    scene = generate_scene(SynthConfig(views=12, res=128, path=path, seed=1), tmp_path / "s", progress=False).root
    permuted_masks(scene, "perm")
    build_masks(
        scene,
        BuildConfig(proposer="existing", from_masks="perm", associate=method, min_area=20, out_masks="out"),
        progress=False,
    )
    gt = [v.load_mask() for v in load_scene(scene, masks=GT_MASKS).views]
    before = [v.load_mask() for v in load_scene(scene, masks="perm").views]
    after = [v.load_mask() for v in load_scene(scene, masks="out").views]
    assert consistent_fraction(before, gt) < 0.6
    assert consistent_fraction(after, gt) >= 0.97


def views_of_different_sizes(scene_dir: Path) -> None:
    """Crop 1 to 3 px off the right and bottom of every other view (its image, mask and
    camera), as undistortion with a camera per image leaves a capture."""
    from dataset_tools import colmap
    from dataset_tools.image_files import read_image, read_mask

    scene = load_scene(scene_dir, masks=GT_MASKS)
    cameras = []
    for k, v in enumerate(scene.views):
        cut = (k % 3) + 1 if k % 2 else 0
        camera = replace(v.camera, width=v.camera.width - cut, height=v.camera.height - cut)
        if cut:
            write_png(v.image_path, read_image(v.image_path)[:-cut, :-cut])
            write_png(v.mask_path, read_mask(v.mask_path)[:-cut, :-cut])
        cameras.append(camera)
    keep = [(ids, uv) for ids, uv in ((v.point_ids, v.uv) for v in scene.views)]
    keep = [
        (ids[(uv < [c.width, c.height]).all(1)], uv[(uv < [c.width, c.height]).all(1)])
        for (ids, uv), c in zip(keep, cameras)
    ]
    colmap.write_model(
        scene_dir / "sparse" / "0",
        [v.name for v in scene.views],
        cameras,
        [v.cam_from_world for v in scene.views],
        keep,
        scene.points.xyz,
        scene.points.rgb,
    )


@pytest.mark.parametrize("method", ["flow", "tracks"])
def test_views_of_different_sizes_build_with_each_association(tmp_path, method):
    """Every place that relates two views (flow, consensus, association) takes views whose
    sizes differ by a few pixels, and the masks come out at each view's own size."""
    scene = generate_scene(
        SynthConfig(views=10, res=96, objects=3, path="forward", seed=2), tmp_path / "s", progress=False
    ).root
    views_of_different_sizes(scene)
    permuted_masks(scene, "perm")
    build_masks(
        scene, BuildConfig(proposer="existing", from_masks="perm", associate=method, out_masks="out"), progress=False
    )
    out = load_scene(scene, masks="out").views
    gt = [v.load_mask() for v in load_scene(scene, masks=GT_MASKS).views]
    assert len({v.load_mask().shape for v in out}) > 1
    assert all(v.load_mask().shape == g.shape for v, g in zip(out, gt))
    assert consistent_fraction([v.load_mask() for v in out], gt) >= 0.97


def test_dataset_export_round_trips(scene_copy, tmp_path):
    import datasets

    permuted_masks(scene_copy, "perm")
    build_masks(
        scene_copy,
        BuildConfig(
            proposer="existing",
            from_masks="perm",
            associate="tracks",
            min_area=20,
            out_masks="out",
            dataset=str(tmp_path / "ds"),
        ),
        progress=False,
    )
    ds = datasets.load_from_disk(str(tmp_path / "ds"))
    assert len(ds) == 8 and ds[0]["view"] == "0000" and ds[0]["split"] == "test"
    assert np.array_equal(np.array(ds[3]["mask"]), load_scene(scene_copy, masks="out").views[3].load_mask())
    assert list((tmp_path / "ds" / "parquet").glob("*.parquet"))


def test_clean_writes_a_new_folder(scene_copy):
    permuted_masks(scene_copy, "perm")
    clean_scene_masks(scene_copy, "perm", "cleaned", min_area=20, progress=False)
    assert len(list((scene_copy / "cleaned").glob("*.png"))) == 8


@pytest.mark.parametrize(
    "options, message",
    [
        ({"proposer": "nope"}, "unknown proposer"),
        ({"proposer": "sam-hq"}, "sam-hq"),
        ({"proposer": "existing"}, "needs from_masks"),
        ({"proposer": "existing", "from_masks": "missing", "out_masks": "x"}, "mask folder not found"),
        ({"associate": "magic"}, "use auto, flow, tracks"),
        ({"out_masks": "object_mask"}, "already exists"),
    ],
)
def test_bad_options_are_refused_before_writing(scene_copy, options, message):
    """By the options when they are made, or by the build before it writes."""
    with pytest.raises(InputError, match=message):
        build_masks(scene_copy, BuildConfig(**options), progress=False)
    assert not (scene_copy / "x").exists()


def test_masks_of_the_wrong_size_exit_2(scene_copy):
    write_png(scene_copy / "bad" / "0000.png", np.zeros((10, 10), np.uint8))
    hq = str(Path(sys.executable).parent / "hqmask")
    r = subprocess.run(
        [hq, "build", str(scene_copy), "--proposer", "existing", "--from-masks", "bad", "--out-masks", "o"],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 2 and "mask is 10x10" in r.stderr and "Traceback" not in r.stderr
    assert not (scene_copy / "o").exists()


def test_more_than_255_tracks_is_refused_with_the_fix():
    from hqmask.association.common import compact_ids

    segments = [np.arange(300, dtype=np.int32).reshape(15, 20) + 1]  # 300 one-pixel segments
    with pytest.raises(InputError, match="found 300 objects, more than the 255.*raise min_area"):
        compact_ids([np.arange(-1, 300)], segments)
    ids = compact_ids([np.arange(-1, 255)], [np.minimum(segments[0], 255)])[0]
    assert ids.max() == 255 and len(np.unique(ids)) == 255


def test_tracks_splits_a_mask_that_merges_two_objects(tmp_path):
    """View 3 labels two touching objects with one ID; the other views tell them apart, and
    the SfM points inside the merged segment split it between them."""
    scene = generate_scene(SynthConfig(views=12, res=128, path="orbit", seed=1), tmp_path / "s", progress=False).root
    views = load_scene(scene, masks=GT_MASKS).views
    gt = [v.load_mask() for v in views]
    counts = np.bincount(gt[3].ravel(), minlength=256)
    a, b = np.argsort(counts[1:])[-2:] + 1  # the two largest objects of view 3
    for k, v in enumerate(views):
        m = gt[k].copy()
        if k == 3:
            m[m == b] = a
        write_png(scene / "merged" / f"{v.stem}.png", m)
    build_masks(
        scene,
        BuildConfig(proposer="existing", from_masks="merged", associate="tracks", min_area=20, out_masks="out"),
        progress=False,
    )
    out = load_scene(scene, masks="out").views[3].load_mask()
    mapping = match_ids(sum(overlap(o.load_mask(), g) for o, g in zip(load_scene(scene, masks="out").views, gt)))
    for obj in (a, b):
        assert np.mean(mapping[out[gt[3] == obj]] == obj) > 0.8, obj


def test_tracks_keeps_an_object_whose_mask_bleeds_into_the_floor(tmp_path):
    """View 3's mask of an object bleeds into the background around it until most SfM points
    of the segment lie on the floor: the segment is split by nearest point, the object keeps
    its pixels and the floor goes back to background (not the whole segment to background)."""
    scene = generate_scene(SynthConfig(views=12, res=128, path="orbit", seed=1), tmp_path / "s", progress=False).root
    views = load_scene(scene, masks=GT_MASKS).views
    gt = [v.load_mask() for v in views]
    counts = np.bincount(gt[3].ravel(), minlength=256)
    obj = int(np.argsort(counts[1:])[-2] + 1)  # the second largest object of view 3
    grown = cv2.dilate((gt[3] == obj).astype(np.uint8), np.ones((25, 25), np.uint8)).astype(bool)
    bleed = grown & (gt[3] == 0)
    for k, v in enumerate(views):
        m = gt[k].copy()
        if k == 3:
            m[bleed] = obj
        write_png(scene / "bleed" / f"{v.stem}.png", m)
    build_masks(
        scene,
        BuildConfig(proposer="existing", from_masks="bleed", associate="tracks", min_area=20, out_masks="out"),
        progress=False,
    )
    out = [o.load_mask() for o in load_scene(scene, masks="out").views]
    mapping = match_ids(sum(overlap(o, g) for o, g in zip(out, gt)))
    assert np.mean(mapping[out[3][gt[3] == obj]] == obj) > 0.85
    assert np.mean(out[3][bleed] == 0) > 0.8


def test_tracks_keeps_an_object_cut_in_half_in_most_views(tmp_path):
    """On a forward-facing capture (every view sees the same side of an object), seven of
    the twelve views that see it lose its left half (a mask that misses part of a small
    object); its left points lie in background in those views and in the object in the
    others. A background vote counts half, so those points stay the object's and the views
    that saw it whole keep all of it (at equal weights the object's segments there were
    split, their left halves given to background)."""
    scene = generate_scene(SynthConfig(views=12, res=128, path="forward", seed=1), tmp_path / "s", progress=False).root
    views = load_scene(scene, masks=GT_MASKS).views
    gt = [v.load_mask() for v in views]
    obj = int(np.argsort(np.bincount(gt[3].ravel(), minlength=256)[1:])[-2] + 1)
    seen = [k for k in range(len(views)) if (gt[k] == obj).sum() >= 50]
    cut, whole = seen[:7], seen[7:]
    assert len(whole) >= 3
    for k, v in enumerate(views):
        m = gt[k].copy()
        if k in cut:
            left = np.zeros_like(m, bool)
            left[:, : int(np.median(np.nonzero(m == obj)[1]))] = True
            m[left & (m == obj)] = 0
        write_png(scene / "cut" / f"{v.stem}.png", m)
    build_masks(
        scene,
        BuildConfig(
            proposer="existing", from_masks="cut", associate="tracks", min_area=20, consensus=0, out_masks="out"
        ),
        progress=False,
    )
    out = [o.load_mask() for o in load_scene(scene, masks="out").views]
    mapping = match_ids(sum(overlap(o, g) for o, g in zip(out, gt)))
    for k in whole:
        assert np.mean(mapping[out[k][gt[k] == obj]] == obj) > 0.9, k


def test_tracks_joins_the_pieces_of_a_mask_split_alike_in_two_views(tmp_path):
    """Views 3 and 4 cut the largest object in two along the same vertical line through its
    centre, each half under a new ID: the halves of the two views link to each other, but
    every other view holds their points inside the whole object, so they are pieces of it."""
    scene = generate_scene(SynthConfig(views=12, res=128, path="orbit", seed=1), tmp_path / "s", progress=False).root
    views = load_scene(scene, masks=GT_MASKS).views
    gt = [v.load_mask() for v in views]
    obj = int(np.argmax(np.bincount(gt[3].ravel(), minlength=256)[1:]) + 1)
    for k, v in enumerate(views):
        m = gt[k].copy()
        if k in (3, 4):
            cols = np.nonzero(m == obj)[1]
            left = np.zeros_like(m, bool)
            left[:, : int(cols.mean())] = True
            m[(m == obj) & left] = 201
            m[(m == obj) & ~left] = 202
        write_png(scene / "split" / f"{v.stem}.png", m)
    build_masks(
        scene,
        BuildConfig(proposer="existing", from_masks="split", associate="tracks", min_area=20, out_masks="out"),
        progress=False,
    )
    out = [o.load_mask() for o in load_scene(scene, masks="out").views]
    mapping = match_ids(sum(overlap(o, g) for o, g in zip(out, gt)))
    for k in (3, 4):
        assert np.mean(mapping[out[k][gt[k] == obj]] == obj) > 0.95, k


@pytest.mark.parametrize("method", ["flow", "tracks"])
def test_shuffled_file_names_give_the_same_masks(tmp_path, method):
    """The views are visited in an order their poses give, so renaming the files (as a
    phone's burst or a merged folder names them) changes no view's masks."""
    from dataset_tools.corruption import corrupt_scene
    from pipeline.experiment import shuffled_copy

    scene = generate_scene(
        SynthConfig(views=10, res=96, objects=4, path="orbit", seed=4), tmp_path / "s", progress=False
    ).root
    corrupt_scene(scene, "noisy", "medium", seed=4, progress=False)
    shuffled = shuffled_copy(scene, tmp_path / "shuffled", seed=3)
    for root in (scene, shuffled):
        build_masks(
            root,
            BuildConfig(proposer="existing", from_masks="noisy", associate=method, out_masks="out"),
            progress=False,
        )
    ours = [v.load_mask() for v in load_scene(scene, masks="out").views]
    theirs = {v.image_path.read_bytes(): v.load_mask() for v in load_scene(shuffled, masks="out").views}
    gt = [v.load_mask() for v in load_scene(scene, masks=GT_MASKS).views]
    same_order = [theirs[v.image_path.read_bytes()] for v in load_scene(scene, masks=GT_MASKS).views]
    name_in_copy = {v.image_path.read_bytes(): v.name for v in load_scene(shuffled, masks=GT_MASKS).views}
    assert sum(name_in_copy[v.image_path.read_bytes()] != v.name for v in load_scene(scene, masks=GT_MASKS).views) >= 5
    assert consistent_fraction(same_order, gt) == consistent_fraction(ours, gt)
    mapping = match_ids(sum(overlap(a, b) for a, b in zip(ours, same_order)))
    assert all(np.array_equal(mapping[a], b) for a, b in zip(ours, same_order))


@pytest.mark.slow
def test_graph_masks_give_the_beer_can_one_id_in_every_view(beer, tmp_path):
    """The weight-free proposer on the real capture (71 views at 1/4 size, associated by its SfM
    tracks): one ID is in every view, at the can's size (4-13% of a view); anything else is
    a rare small fragment."""
    (tmp_path / "beer").mkdir()
    for name in ("sparse", "images_4"):
        (tmp_path / "beer" / name).symlink_to(beer / name)
    build_masks(tmp_path / "beer", BuildConfig(proposer="graph", images="images_4"), progress=False)
    masks = [v.load_mask() for v in load_scene(tmp_path / "beer", images="images_4").views]
    present = [set(np.unique(m)) - {0} for m in masks]
    everywhere = set.intersection(*present)
    assert len(masks) == 71 and len(everywhere) == 1
    can = everywhere.pop()
    assert all(0.02 < np.mean(m == can) < 0.2 for m in masks)
    others = [np.mean((m != can) & (m != 0)) for m in masks]
    assert max(others) < 0.01 and np.mean([o > 0 for o in others]) < 0.2


def test_a_damaged_cache_entry_is_proposed_again(scene_copy):
    """One truncated and one foreign file in the graph proposer's cache: the next build
    proposes those views again and writes the masks of a build from an empty cache."""
    build_masks(scene_copy, BuildConfig(proposer="graph", out_masks="first"), progress=False)
    cached = sorted((scene_copy / ".hqmask_cache" / "graph").glob("*.png"))
    cached[0].write_bytes(cached[0].read_bytes()[:50])
    cached[1].write_bytes(cached[2].read_bytes()[:-1] + b"\0")
    build_masks(scene_copy, BuildConfig(proposer="graph", out_masks="second"), progress=False)
    for first in sorted((scene_copy / "first").glob("*.png")):
        assert first.read_bytes() == (scene_copy / "second" / first.name).read_bytes()
    assert read_cached_segments(cached[0]) is not None and read_cached_segments(cached[1]) is not None


def test_every_mask_folder_says_how_it_was_made(small_scene, scene_copy):
    from dataset_tools.inspect_scene import summarize
    from dataset_tools.mask_manifest import read_manifest

    assert read_manifest(small_scene.root / GT_MASKS)["truth"] is True
    build_masks(scene_copy, BuildConfig(out_masks="built", consensus=2), progress=False)
    built = read_manifest(scene_copy / "built")
    assert built["made_by"] == "hqmask build" and built["format"] == 1
    assert (built["proposer"], built["associate"], built["consensus"], built["depth"]) == ("graph", "tracks", 2, None)
    clean_scene_masks(scene_copy, "built", "cleaned", progress=False)
    assert read_manifest(scene_copy / "cleaned")["from_masks"] == "built"
    shown = str(summarize(load_scene(scene_copy, masks="built")))
    assert "made by      hqmask build" in shown and "proposer graph" in shown
    assert "ground truth (dataset_tools synth)" in str(summarize(load_scene(small_scene.root)))
    (scene_copy / "cleaned" / "manifest.json").unlink()
    assert "no manifest" in str(summarize(load_scene(scene_copy, masks="cleaned")))
