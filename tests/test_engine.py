"""Independent work on ``local`` and on a real local Ray cluster: the same results, in order,
and a task's error is the task's own error; work that needs a state first (a proposer) on
actors that make it once."""

from __future__ import annotations

import filecmp
import functools
import shutil
import subprocess

import pytest
from helpers import script

from dataset_tools.infra.engine import Engine
from dataset_tools.infra.errors import InputError
from dataset_tools.infra.names import plain_name
from dataset_tools.scene import load_scene
from hqmask.build import CACHE, BuildConfig, build_masks, propose_view
from hqmask.proposers.registry import make_proposer

# Ray workers import a task's function by name: a library function, not one of this module.
CHECK_NAME = functools.partial(plain_name, option="name")


@pytest.fixture(scope="module")
def ray_engine():
    ray = pytest.importorskip("ray", reason="Ray is not installed (pip install -e .[ray])")
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False, configure_logging=False)
    yield Engine("ray", cpus=1)
    ray.shutdown()


def test_an_engine_is_checked_when_made():
    with pytest.raises(InputError, match="engine='spark'"):
        Engine("spark")
    with pytest.raises(InputError, match="with engine='ray'"):
        Engine("local", address="10.0.0.1:6379")


@pytest.mark.slow
def test_ray_maps_in_order_and_raises_the_tasks_own_error(ray_engine):
    items = [f"scene_{i}" for i in range(7, -1, -1)]
    assert ray_engine.map(CHECK_NAME, items, progress=False) == Engine().map(CHECK_NAME, items, progress=False) == items
    with pytest.raises(InputError, match="'../up': give a plain folder name"):
        ray_engine.map(CHECK_NAME, ["a", "../up", "b"], progress=False)


@pytest.mark.slow
def test_hqmask_build_of_two_scenes_on_ray_writes_the_masks_of_local(small_scene, tmp_path):
    pytest.importorskip("ray", reason="Ray is not installed (pip install -e .[ray])")
    scenes = {
        engine: [shutil.copytree(small_scene.root, tmp_path / engine / name) for name in ("a", "b")]
        for engine in ("local", "ray")
    }
    for engine, paths in scenes.items():
        r = subprocess.run(
            [script("hqmask"), "build", *map(str, paths), "--out-masks", "built", "--engine", engine],
            capture_output=True,
            text=True,
        )
        assert r.returncode == 0, r.stderr
        assert r.stdout.count("wrote") == 2
    for local, ray in zip(scenes["local"], scenes["ray"]):
        names = sorted(p.name for p in (local / "built").iterdir())
        assert names and names == sorted(p.name for p in (ray / "built").iterdir())
        match, mismatch, errors = filecmp.cmpfiles(local / "built", ray / "built", names, shallow=False)
        assert not mismatch and not errors


@pytest.mark.slow
def test_one_scene_has_its_views_proposed_by_ray_workers_as_here(ray_engine, small_scene, tmp_path):
    scenes = {}
    for name, engine in (("local", Engine()), ("ray", ray_engine)):
        scenes[name] = shutil.copytree(small_scene.root, tmp_path / name)
        build_masks(scenes[name], BuildConfig(out_masks="built"), engine=engine, progress=False)
    for folder in ("built", f"{CACHE}/graph"):  # the masks, and the proposals the workers cached
        names = sorted(p.name for p in (scenes["local"] / folder).iterdir())
        assert len([n for n in names if n.endswith(".png")]) == len(list((small_scene.root / "images").iterdir()))
        match, mismatch, errors = filecmp.cmpfiles(
            scenes["local"] / folder, scenes["ray"] / folder, names, shallow=False
        )
        assert match == names
    # A worker whose proposer cannot be made raises that error here.
    view = load_scene(small_scene.root).views[0]
    with pytest.raises(InputError, match="encoder.onnx: missing"):
        ray_engine.map_stateful(
            functools.partial(make_proposer, BuildConfig(proposer="sam-hq", model=str(tmp_path / "no-model"))),
            propose_view,
            [(view.load_image(), view, None, None, None)],
            progress=False,
        )


def test_local_threads_propose_the_views_as_one_thread_does_in_order(small_scene):
    proposer = make_proposer(BuildConfig())
    assert proposer.threadable
    jobs = [(v.load_image(), v, None, None, None) for v in load_scene(small_scene.root).views]
    one, two = (
        Engine().map_stateful(None, propose_view, jobs, local_state=proposer, threads=n, progress=False) for n in (1, 2)
    )
    assert len(one) == len(jobs) and all((a == b).all() for a, b in zip(one, two))
    assert len({a.tobytes() for a in one}) > 1  # the views differ, so the order is checked
    with pytest.raises(InputError, match="'../up': give a plain folder name"):
        Engine().map_stateful(
            None, lambda _, x: CHECK_NAME(x), ["a", "../up", "b"], local_state=0, threads=2, progress=False
        )
