"""The synthetic generator: determinism, COLMAP output, and ground truth that agrees with itself."""

import filecmp
import json
from pathlib import Path

import numpy as np
import pytest

from dataset_tools import InputError, load_scene
from dataset_tools.scene import GT_MASKS
from dataset_tools.synth import SynthConfig, generate_scene
from dataset_tools.synth.generator import observe


def files_of(root):
    return sorted(p.relative_to(root) for p in root.rglob("*") if p.is_file())


def test_same_seed_same_bytes(tmp_path):
    first, again = (
        generate_scene(SynthConfig(views=8, res=96, objects=4, seed=1), tmp_path / name, progress=False)
        for name in ("first", "again")
    )
    names = files_of(first.root)
    assert names == files_of(again.root) and Path(GT_MASKS) / "0000.png" in names
    _, mismatch, errors = filecmp.cmpfiles(first.root, again.root, [str(n) for n in names], shallow=False)
    assert mismatch == [] and errors == []


def test_other_seed_other_scene(small_scene, tmp_path):
    other = generate_scene(SynthConfig(views=8, res=96, objects=4, seed=2), tmp_path / "other", progress=False)
    assert not filecmp.cmp(small_scene.root / "images/0000.png", other.root / "images/0000.png", shallow=False)


def test_pycolmap_reads_the_model_and_observations_reproject(small_scene):
    import pycolmap

    rec = pycolmap.Reconstruction(str(small_scene.root / "sparse" / "0"))
    assert rec.num_reg_images() == 8 and rec.num_points3D() == len(small_scene.point_object_ids)
    assert {c.model.name for c in rec.cameras.values()} == {"PINHOLE"}
    for image in rec.images.values():
        cam = rec.cameras[image.camera_id]
        for p in image.points2D:
            uv = cam.img_from_cam(image.cam_from_world() * rec.points3D[p.point3D_id].xyz)
            assert np.allclose(uv, p.xy, atol=1e-6)
    assert all(pt.track.length() >= 2 for pt in rec.points3D.values())


@pytest.mark.parametrize("path", ["orbit", "forward"])
def test_point_ids_agree_with_masks_in_observing_views(tmp_path, path):
    res = generate_scene(SynthConfig(views=12, res=128, objects=6, path=path, seed=4), tmp_path / path, progress=False)
    scene = load_scene(res.root, masks=GT_MASKS)
    agree = total = 0
    for v in scene.views:
        mask = v.load_mask()
        px = v.uv.astype(int)
        agree += np.sum(mask[px[:, 1], px[:, 0]] == res.point_object_ids[v.point_ids])
        total += len(v.point_ids)
    assert total > 1000
    assert agree / total >= 0.99
    assert set(np.unique(res.point_object_ids)) == set(range(7))  # every object and the background


def test_every_object_is_seen_and_occlusion_is_exact(small_scene):
    scene = load_scene(small_scene.root)
    ids = set()
    for v in scene.views:
        ids.update(np.unique(v.load_mask()).tolist())
    assert ids == {0, 1, 2, 3, 4}
    # a point hidden behind an object in a view is not observed there: observe() drops it
    view = scene.views[0]
    depth = np.full((96, 96), 1.0)
    behind = np.array([view.center + 3.0 * view.R[2]])  # on the optical axis, 3 units away
    rows, _ = observe(behind, view.camera, view.cam_from_world, depth)
    assert len(rows) == 0
    rows, _ = observe(behind, view.camera, view.cam_from_world, np.full((96, 96), 3.0))
    assert len(rows) == 1


def test_scene_json_describes_objects(small_scene):
    meta = json.loads((small_scene.root / "scene.json").read_text())
    assert sorted(meta["objects"]) == ["1", "2", "3", "4"]
    assert meta["provenance"]["config"]["seed"] == 1
    assert meta["split"]["test"] == ["0000.png"]


def test_too_many_objects_is_refused(tmp_path):
    with pytest.raises(InputError, match="255"):
        generate_scene(SynthConfig(objects=300), tmp_path / "x", progress=False)
    assert not (tmp_path / "x").exists()


def test_failed_generation_leaves_nothing(tmp_path, monkeypatch):
    from dataset_tools.synth import generator

    calls = []

    def failing(*args, **kwargs):
        calls.append(1)
        if len(calls) == 3:
            raise RuntimeError("interrupted")
        return real(*args, **kwargs)

    real = generator.render_view
    monkeypatch.setattr(generator, "render_view", failing)
    with pytest.raises(RuntimeError):
        generate_scene(SynthConfig(views=4, res=32, objects=2), tmp_path / "out", progress=False)
    assert list(tmp_path.iterdir()) == []
