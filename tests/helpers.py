"""What several test modules share: command-line runners, synthetic scenes with training
masks, small random Gaussian scenes, numba's thread count and the plumbing tests' fill."""

from __future__ import annotations

import shutil
import subprocess
import sys
from contextlib import contextmanager
from pathlib import Path

import numba
import numpy as np
import torch

from dataset_tools.cameras import PinholeCamera
from dataset_tools.infra.atomic import write_bytes_atomic
from dataset_tools.mask_manifest import MANIFEST, manifest_bytes
from dataset_tools.scene import GT_MASKS, MASKS
from dataset_tools.synth import SynthConfig, SynthResult, generate_scene
from gsseg.fill_options import FillOptions
from gsseg.model.gaussians import Gaussians

QUICK_FILL = FillOptions(steps=60)  # a removal's fill in the plumbing tests, which do not look at what it fits


def run(*args: str, **kwargs) -> subprocess.CompletedProcess:
    """Run a command, capturing its text output."""
    return subprocess.run(args, capture_output=True, text=True, **kwargs)


def script(name: str) -> str:
    """A console script installed beside this interpreter (works without an activated venv)."""
    return str(Path(sys.executable).parent / name)


def scene_with_exact_masks(cfg: SynthConfig, out: Path) -> SynthResult:
    """A synthetic scene whose training masks (``object_mask/``) are a copy of its ground truth
    (``gt_mask/``): the masks a perfect proposer would build, so that a test of training,
    segmentation or editing knows the answer."""
    result = generate_scene(cfg, out, progress=False)
    shutil.copytree(result.root / GT_MASKS, result.root / MASKS, ignore=shutil.ignore_patterns(MANIFEST))
    write_bytes_atomic(result.root / MASKS / MANIFEST, manifest_bytes("tests", copy_of=GT_MASKS))
    return result


GEOMETRY = ("means", "log_scales", "quats", "opacity_logits")  # the Gaussian fields that place and shape them


def random_gaussians(
    n: int, seed: int, dtype: torch.dtype = torch.float32, scales: tuple[float, float] = (0.04, 0.24)
) -> Gaussians:
    """``n`` Gaussians in front of :func:`look_down_z`, with varied shapes (axis standard
    deviations drawn in ``scales``), opacities, SH colours and object features."""
    gen = torch.Generator().manual_seed(seed)

    def rand(*shape: int) -> torch.Tensor:
        return torch.rand(*shape, generator=gen, dtype=torch.float64)

    means = (rand(n, 3) - 0.5) * torch.tensor([2.4, 1.8, 2.0], dtype=torch.float64)
    g = Gaussians(
        means=means,
        log_scales=torch.log(scales[0] + (scales[1] - scales[0]) * rand(n, 3)),
        quats=rand(n, 4) - 0.5,
        opacity_logits=8 * rand(n) - 2,
        sh_dc=rand(n, 3) * 2 - 1,
        sh_rest=0.2 * (rand(n, 15, 3) - 0.5),
        obj_feat=rand(n, 16) - 0.5,
    )
    return Gaussians(**{k: v.to(dtype) for k, v in g.tensors().items()})


def look_down_z(width: int = 40, height: int = 32, distance: float = 3.5) -> tuple[PinholeCamera, torch.Tensor]:
    """A camera ``distance`` in front of the origin looking along +z, and its (3, 4) pose."""
    f = 0.9 * width
    pose = torch.tensor([[1.0, 0, 0, 0.05], [0, 1, 0, -0.03], [0, 0, 1, distance]], dtype=torch.float64)
    return PinholeCamera(width, height, f, f, width / 2 + 0.3, height / 2 - 0.2), pose


def weighted_sum(out, weights: dict[str, torch.Tensor]) -> torch.Tensor:
    """A scalar loss touching every output of a render: sum of each output times fixed weights."""
    return sum((getattr(out, name) * w).sum() for name, w in weights.items())


def output_weights(width: int, height: int, seed: int, dtype: torch.dtype) -> dict[str, torch.Tensor]:
    rng = np.random.default_rng(seed)
    shapes = {
        "rgb": (height, width, 3),
        "features": (height, width, 16),
        "alpha": (height, width),
        "depth": (height, width),
    }
    return {k: torch.as_tensor(rng.standard_normal(s), dtype=dtype) for k, s in shapes.items()}


@contextmanager
def numba_threads(n: int):
    """numba's parallel kernels on ``n`` threads within the block."""
    before = numba.get_num_threads()
    numba.set_num_threads(min(n, numba.config.NUMBA_NUM_THREADS))
    try:
        yield
    finally:
        numba.set_num_threads(before)
