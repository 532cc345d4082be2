"""Scenes the benchmarks share."""

from __future__ import annotations

from pathlib import Path

from dataset_tools.corrupt import corrupt_scene
from dataset_tools.synth import SynthConfig, generate_scene


def corrupted_scene(root: Path, path: str, *, res: int, severity: str, seed: int, views: int = 24) -> Path:
    """A synthetic scene at ``root/path`` (camera path ``orbit`` or ``forward``) with its exact
    masks in ``object_mask/`` and masks corrupted at ``severity`` in ``noisy/``."""
    scene = generate_scene(SynthConfig(views=views, res=res, path=path, seed=seed), root / path, progress=False).root
    corrupt_scene(scene, "noisy", severity, seed=seed, progress=False)
    return scene
