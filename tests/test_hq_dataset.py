"""The HQ dataset loader, on stand-ins made by the synthetic generator in each of the layouts it
accepts (scene folders, archives of them, `datasets` rows). The real dataset cannot be
downloaded here; the offline path is tested for its message."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tarfile

import numpy as np
import pytest

from dataset_tools import load_scene
from dataset_tools.dataset_rows import export_dataset
from dataset_tools.hq_dataset import convert_hq


def assert_same_scene(a, b) -> None:
    """Same views, pixels, masks, cameras, poses and split."""
    sa, sb = load_scene(a), load_scene(b)
    assert [v.stem for v in sa.views] == [v.stem for v in sb.views]
    assert {v.stem for v in sa.split("test")} == {v.stem for v in sb.split("test")}
    for va, vb in zip(sa.views, sb.views):
        assert np.array_equal(va.load_image(), vb.load_image())
        assert np.array_equal(va.load_mask(), vb.load_mask())
        assert va.camera.K == pytest.approx(vb.camera.K)
        assert va.cam_from_world == pytest.approx(vb.cam_from_world, abs=1e-9)


@pytest.fixture
def standin(small_scene, tmp_path):
    """A repository snapshot: one scene folder under data/, one as a .tar.gz under archives/."""
    root = tmp_path / "snapshot"
    shutil.copytree(small_scene.root, root / "data" / "figurines")
    (root / "archives").mkdir()
    with tarfile.open(root / "archives" / "teatime.tar.gz", "w:gz") as t:
        t.add(small_scene.root, arcname="teatime")
    (root / "README.md").write_text("stand-in\n")
    return root


def test_scene_folders_and_archives_convert_to_identical_scenes(standin, small_scene, tmp_path):
    written = convert_hq(standin, tmp_path / "out", progress=False)
    assert [p.name for p in written] == ["figurines", "teatime"]
    for path in written:
        assert_same_scene(path, small_scene.root)


def test_a_single_archive_and_a_scene_filter(standin, tmp_path):
    written = convert_hq(standin / "archives" / "teatime.tar.gz", tmp_path / "out", progress=False)
    assert [p.name for p in written] == ["teatime"]
    assert [p.name for p in convert_hq(standin, tmp_path / "two", scenes=["figurines"], progress=False)] == [
        "figurines"
    ]


def test_dataset_rows_convert_to_scene_folders(small_scene, tmp_path):
    """Rows as `hqmask build --dataset` writes them (save_to_disk folder and parquet) come
    back as scene folders with the same pixels, cameras, poses and split."""
    export_dataset(load_scene(small_scene.root), tmp_path / "rows")
    shutil.rmtree(tmp_path / "rows" / "parquet")
    (scene,) = convert_hq(tmp_path / "rows", tmp_path / "from_disk", progress=False)
    assert scene.name == small_scene.root.name
    assert_same_scene(scene, small_scene.root)

    export_dataset(load_scene(small_scene.root), tmp_path / "rows2")
    parquet_only = tmp_path / "hub"
    shutil.copytree(tmp_path / "rows2" / "parquet", parquet_only / "data")
    (scene,) = convert_hq(parquet_only, tmp_path / "from_parquet", progress=False)
    assert_same_scene(scene, small_scene.root)


def test_existing_output_is_kept_without_force(standin, tmp_path):
    convert_hq(standin, tmp_path / "out", scenes=["figurines"], progress=False)
    marker = tmp_path / "out" / "figurines" / "marker"
    marker.write_text("mine")
    with pytest.raises(Exception, match="already exists"):
        convert_hq(standin, tmp_path / "out", scenes=["figurines"], progress=False)
    assert marker.read_text() == "mine"
    convert_hq(standin, tmp_path / "out", scenes=["figurines"], overwrite=True, progress=False)
    assert not marker.exists()


def _cli_error(*args: str, **env: str) -> str:
    """Run `python -m dataset_tools hq`, check it failed with exit code 2, return its error line."""
    r = subprocess.run(
        [sys.executable, "-m", "dataset_tools", "hq", *args], capture_output=True, text=True, env={**os.environ, **env}
    )
    assert r.returncode == 2, r.stderr
    errors = [line for line in r.stderr.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and r.stderr.rstrip().endswith(errors[0]), r.stderr
    return errors[0]


def test_offline_download_says_so_and_points_to_local(tmp_path):
    error = _cli_error("--out", str(tmp_path / "out"), HF_HUB_OFFLINE="1", HF_HOME=str(tmp_path / "hf"))
    assert "cannot download joshir/3D-Scene-Segmentation-HQ" in error and "--local" in error
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(
    "make, message",
    [
        (lambda p: p / "missing", "no such dataset path"),
        (lambda p: (p / "empty").mkdir() or p / "empty", "found no scenes"),
        (lambda p: (p / "bad.zip").write_bytes(b"not a zip") and p / "bad.zip", "damaged archive"),
    ],
)
def test_bad_dataset_paths(tmp_path, make, message):
    assert message in _cli_error("--out", str(tmp_path / "out"), "--local", str(make(tmp_path)))
