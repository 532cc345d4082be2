"""Shared fixtures: small synthetic scenes made once per test session. Tests that need a trained
run are marked ``slow`` (the run takes tens of seconds); ``python -m pytest -m "not slow"``
leaves them out."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from helpers import scene_with_exact_masks

from dataset_tools.synth import SynthConfig, SynthResult

BEER = Path(__file__).resolve().parents[2] / "shared" / "data" / "beer"
SLOW_FIXTURES = {"trained", "segmented"}


def pytest_collection_modifyitems(items) -> None:
    for item in items:
        if SLOW_FIXTURES & set(getattr(item, "fixturenames", ())):
            item.add_marker(pytest.mark.slow)


@pytest.fixture(scope="session")
def small_scene(tmp_path_factory) -> SynthResult:
    """An 8-view 96x96 orbit scene with 4 objects, its ground truth copied as its training masks
    (read-only: copy it before changing it)."""
    return scene_with_exact_masks(
        SynthConfig(views=8, res=96, objects=4, seed=1), tmp_path_factory.mktemp("s") / "small"
    )


@pytest.fixture
def scene_copy(small_scene, tmp_path) -> Path:
    """A private, writable copy of ``small_scene``."""
    dst = tmp_path / "scene"
    shutil.copytree(small_scene.root, dst)
    return dst


@pytest.fixture(scope="session")
def trained(small_scene, tmp_path_factory) -> Path:
    """The run folder of ``small_scene`` trained for 200 CPU iterations (read-only)."""
    from gsseg.train.config import TrainConfig
    from gsseg.train.trainer import train

    run = tmp_path_factory.mktemp("runs") / "fit"
    train(small_scene.root, run, TrainConfig(iters=200, backend="cpu"), progress=False)
    return run


@pytest.fixture(scope="session")
def segmented(trained, small_scene, tmp_path_factory) -> Path:
    """A copy of ``trained`` with ``labels.npz`` and ``contributions.npz`` from the scene's masks
    (read-only: copy it before changing it)."""
    from gsseg.segment.segment_run import segment_run

    run = tmp_path_factory.mktemp("seg") / "run"
    shutil.copytree(trained, run)
    segment_run(run, small_scene.root, backend="cpu", progress=False)
    return run


@pytest.fixture
def beer() -> Path:
    if not (BEER / "sparse" / "0").is_dir():
        pytest.skip(f"the beer capture is not at {BEER}")
    return BEER
