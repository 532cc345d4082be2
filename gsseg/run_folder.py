"""The run folder of DESIGN.md: what training writes and what segmenting, editing and
rendering read.

    run/
      config.json      every option of the run
      gaussians.ply    3D-GS PLY + obj_feat_0..15
      classifier.pt    the 16 -> num_classes linear layer
      environment.pt   the learned background (SH of the ray direction), when the run has one
      checkpoints/     resumable state
      metrics.json     the training curve
"""

from __future__ import annotations

import io
import json
from dataclasses import dataclass
from pathlib import Path

import torch

from dataset_tools.atomic import write_bytes_atomic
from dataset_tools.errors import InputError
from gsseg.environment import Environment
from gsseg.gaussians import OBJ_FEAT_DIM, Gaussians
from gsseg.ply import read_ply

CONFIG = "config.json"
GAUSSIANS = "gaussians.ply"
CLASSIFIER = "classifier.pt"
ENVIRONMENT = "environment.pt"
CHECKPOINTS = "checkpoints"
METRICS = "metrics.json"


def make_classifier(num_classes: int = 256) -> torch.nn.Linear:
    """The linear layer from object features to class logits."""
    return torch.nn.Linear(OBJ_FEAT_DIM, num_classes)


def write_json(path: Path, data: dict) -> None:
    write_bytes_atomic(path, (json.dumps(data, indent=2) + "\n").encode())


def write_torch(path: Path, obj) -> None:
    buf = io.BytesIO()
    torch.save(obj, buf)
    write_bytes_atomic(path, buf.getvalue())


@dataclass
class Run:
    """A trained run, loaded."""

    root: Path
    config: dict
    gaussians: Gaussians
    classifier: torch.nn.Linear
    environment: Environment | None = None  # None: the run renders on black


def load_run(root: Path | str) -> Run:
    """Load the model of a finished (or checkpointed and exported) training run."""
    root = Path(root)
    for name in (CONFIG, GAUSSIANS, CLASSIFIER):
        if not (root / name).is_file():
            raise InputError(f"{root} has no {name}; point to the --out folder of a finished `gsseg train`.")
    config = json.loads((root / CONFIG).read_text())
    state = torch.load(root / CLASSIFIER, map_location="cpu", weights_only=True)
    classifier = make_classifier(state["weight"].shape[0])
    classifier.load_state_dict(state)
    environment = None
    if (root / ENVIRONMENT).is_file():
        environment = Environment.from_state(torch.load(root / ENVIRONMENT, map_location="cpu", weights_only=True))
    return Run(root=root, config=config, gaussians=read_ply(root / GAUSSIANS), classifier=classifier,
               environment=environment)
