"""Scene folders: loading, saving, splits, undistortion and the errors users meet."""

import shutil
import subprocess
import sys

import cv2
import numpy as np
import pytest

from dataset_tools import InputError, load_scene, save_scene
from dataset_tools.cameras import DEFAULT_NEAR
from dataset_tools.colmap import ColmapImage, read_model
from dataset_tools.image_files import write_png
from dataset_tools.scene import llff_test_names, scene_near_plane


def assert_same_scene(a, b):
    assert [v.name for v in a.views] == [v.name for v in b.views]
    for va, vb in zip(a.views, b.views):
        assert va.camera.K == pytest.approx(vb.camera.K, abs=1e-9)
        assert (va.camera.width, va.camera.height) == (vb.camera.width, vb.camera.height)
        assert np.allclose(va.cam_from_world, vb.cam_from_world, atol=1e-9)
        assert np.array_equal(va.load_image(), vb.load_image())
        assert np.array_equal(va.load_mask(), vb.load_mask())
        assert np.array_equal(va.point_ids, vb.point_ids)
        assert np.allclose(va.uv, vb.uv, atol=1e-9)
    assert np.allclose(a.points.xyz, b.points.xyz, atol=1e-12)
    assert np.array_equal(a.points.rgb, b.points.rgb)
    assert a.test_names == b.test_names


@pytest.mark.parametrize("text", [False, True])
def test_save_load_round_trip(small_scene, tmp_path, text):
    a = load_scene(small_scene.root)
    save_scene(a, tmp_path / "copy", text=text)
    assert (tmp_path / "copy" / "sparse" / "0" / ("images.txt" if text else "images.bin")).exists()
    assert_same_scene(a, load_scene(tmp_path / "copy"))


def test_llff_split_takes_every_eighth_view_by_name():
    names = [f"{k:03d}.jpg" for k in range(20)][::-1]
    assert llff_test_names(names) == {"000.jpg", "008.jpg", "016.jpg"}


def test_near_plane_is_half_the_nearest_depth_a_view_observes():
    xyz = np.stack([np.zeros(201), np.zeros(201), np.linspace(-1.0, 199.0, 201)], axis=1)  # depths -1..199 along +z
    pose = np.hstack([np.eye(3), np.zeros((3, 1))])
    moved = np.hstack([np.eye(3), [[0.0], [0.0], [4.0]]])  # sees every point 4 deeper

    def image(cam_from_world, ids):
        return ColmapImage("v", None, cam_from_world, np.asarray(ids, np.int64), np.zeros((len(ids), 2)))

    # the first view's positive depths are 1..199 (1st percentile 2.98); the second's 3..203
    near = scene_near_plane([image(pose, range(201)), image(moved, range(201)), image(pose, [])], xyz)
    assert near == pytest.approx(0.5 * np.percentile(np.arange(1.0, 200.0), 1.0))
    assert scene_near_plane([image(pose, [])], xyz) == DEFAULT_NEAR


def test_every_camera_of_a_scene_gets_its_near_plane(small_scene):
    model = read_model(small_scene.root / "sparse" / "0")
    near = scene_near_plane(model.images, model.xyz)
    assert 0 < near < 10 and near != DEFAULT_NEAR
    assert {v.camera.near for v in load_scene(small_scene.root).views} == {near}


def test_scene_json_split_overrides_llff(scene_copy):
    (scene_copy / "scene.json").write_text('{"split": {"test": ["0003.png", "0005.png"]}}')
    scene = load_scene(scene_copy)
    assert [v.name for v in scene.split("test")] == ["0003.png", "0005.png"]
    assert len(scene.split("train")) == 6


def test_loading_reads_no_pixels(small_scene, monkeypatch):
    from dataset_tools import scene as scene_module

    def forbidden(*_):
        raise AssertionError("pixels read during load")

    monkeypatch.setattr(scene_module, "read_image", forbidden)
    monkeypatch.setattr(scene_module, "read_mask", forbidden)
    scene = load_scene(small_scene.root)
    assert len(scene.views) == 8


def test_view_without_mask_is_unsupervised(scene_copy):
    (scene_copy / "object_mask" / "0002.png").unlink()
    scene = load_scene(scene_copy)
    assert scene.view("0002").load_mask() is None
    assert scene.view("0003").load_mask() is not None


def test_full_size_masks_follow_downsampled_images(scene_copy):
    (scene_copy / "images_2").mkdir()
    for p in (scene_copy / "images").iterdir():
        img = cv2.imread(str(p))
        cv2.imwrite(str(scene_copy / "images_2" / p.name), cv2.resize(img, (48, 48), interpolation=cv2.INTER_AREA))
    full = load_scene(scene_copy)
    half = load_scene(scene_copy, images="images_2")
    v_full, v_half = full.views[1], half.views[1]
    assert v_half.camera.fx == pytest.approx(v_full.camera.fx / 2)
    assert v_half.load_image().shape == (48, 48, 3)
    assert np.array_equal(v_half.load_mask(), v_full.load_mask()[::2, ::2][:48, :48]) or (
        np.mean(v_half.load_mask() == cv2.resize(v_full.load_mask(), (48, 48), interpolation=cv2.INTER_NEAREST_EXACT))
        == 1
    )
    assert np.allclose(v_half.uv, v_full.uv / 2)


def test_beer_loads_with_undistorted_pinhole_cameras(beer):
    scene = load_scene(beer, images="images_4")
    assert len(scene.views) == 71 and len(scene.split("test")) == 9
    errors = []
    for v in scene.views[::10]:
        img = v.load_image()
        assert img.shape == (v.camera.height, v.camera.width, 3)
        assert v.source_camera.model == "SIMPLE_RADIAL"
        pc = scene.points.xyz[v.point_ids] @ v.R.T + v.t
        uv = pc[:, :2] / pc[:, 2:] * [v.camera.fx, v.camera.fy] + [v.camera.cx, v.camera.cy]
        errors.append(np.median(np.linalg.norm(uv - v.uv, axis=1)))
    # COLMAP's mean reprojection error is 0.75 px at full size, i.e. about 0.19 px at 1/4
    assert np.median(errors) < 0.4


def test_png_writes_survive_loading_a_colmap_model(small_scene, tmp_path):
    """pycolmap imported before the image libraries aborts later PNG writes: stay safe."""
    code = (
        "import sys, numpy as np\n"
        "from dataset_tools import load_scene\n"
        "from dataset_tools.image_files import write_png, read_mask\n"
        f"s = load_scene({str(small_scene.root)!r})\n"
        f"write_png({str(tmp_path / 'a.png')!r}, s.views[0].load_mask())\n"
        "import PIL.Image\n"
        f"PIL.Image.fromarray(np.zeros((4, 4), np.uint8)).save({str(tmp_path / 'b.png')!r})\n"
        f"assert (read_mask({str(tmp_path / 'a.png')!r}) == s.views[0].load_mask()).all()\n"
    )
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr


# ---------------------------------------------------------------- bad input


def test_missing_sparse_model(scene_copy):
    shutil.rmtree(scene_copy / "sparse")
    with pytest.raises(InputError, match=r"sparse/0.*COLMAP model folder not found"):
        load_scene(scene_copy)


def test_image_listed_in_colmap_but_missing(scene_copy):
    (scene_copy / "images" / "0004.png").unlink()
    with pytest.raises(InputError, match=r"0004\.png: image listed in the COLMAP model is missing"):
        load_scene(scene_copy)


def test_mask_of_wrong_size(scene_copy):
    cv2.imwrite(str(scene_copy / "object_mask" / "0001.png"), np.zeros((50, 60), np.uint8))
    with pytest.raises(InputError, match=r"0001\.png: mask is 60x50 but its image is 96x96"):
        load_scene(scene_copy).view("0001").load_mask()


def test_colour_mask_is_refused(scene_copy):
    cv2.imwrite(str(scene_copy / "object_mask" / "0001.png"), np.zeros((96, 96, 3), np.uint8))
    with pytest.raises(InputError, match="3 channels"):
        load_scene(scene_copy).view("0001").load_mask()


def test_more_than_255_ids_is_refused(scene_copy):
    cv2.imwrite(str(scene_copy / "object_mask" / "0001.png"), np.arange(96 * 96, dtype=np.uint16).reshape(96, 96))
    with pytest.raises(InputError, match="more than the 255"):
        load_scene(scene_copy).view("0001").load_mask()


def test_save_refuses_existing_folder_and_leaves_it(small_scene, tmp_path):
    (tmp_path / "taken").mkdir()
    (tmp_path / "taken" / "keep.txt").write_text("x")
    with pytest.raises(InputError, match="already exists"):
        save_scene(load_scene(small_scene.root), tmp_path / "taken")
    assert [p.name for p in (tmp_path / "taken").iterdir()] == ["keep.txt"]


def test_masks_of_undistorted_views_go_back_to_the_file_frame(beer, tmp_path):
    """An ID map made on an undistorted view is stored at the file's size, and loading it
    undistorts it back to (nearly) the same map."""
    view = load_scene(beer, images="images_4", masks=None).views[0]
    h, w = view.camera.height, view.camera.width
    ids = (np.arange(w)[None, :] // 40 + 8 * (np.arange(h)[:, None] // 40)).astype(np.uint8)
    stored = view.to_file_frame(ids)
    assert (stored.shape[1], stored.shape[0]) == view.file_size != (w, h)
    write_png(tmp_path / "m.png", stored)
    view.mask_path = tmp_path / "m.png"
    assert np.mean(view.load_mask() == ids) > 0.98


def test_a_synthetic_scene_from_before_gt_mask_reads_its_truth_with_a_note(small_scene, tmp_path):
    """Old synthetic scenes kept their exact masks in ``object_mask/`` (marked as ground truth
    by the manifest): asked for ``gt_mask``, they answer with those, and say so."""
    from dataset_tools.scene import GT_MASKS, MASKS

    old = tmp_path / "old"
    shutil.copytree(small_scene.root, old, ignore=shutil.ignore_patterns(MASKS))
    (old / GT_MASKS).rename(old / MASKS)
    with pytest.warns(UserWarning, match="from before gt_mask/"):
        scene = load_scene(old, masks=GT_MASKS)
    assert scene.mask_dir == MASKS
    expected = load_scene(small_scene.root, masks=GT_MASKS).views[2].load_mask()
    np.testing.assert_array_equal(scene.views[2].load_mask(), expected)
    (old / MASKS / "manifest.json").unlink()  # masks of another tool: never taken for the truth
    assert load_scene(old, masks=GT_MASKS).mask_dir is None
