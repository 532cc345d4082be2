"""The run folder, the contract between training, segmentation, editing and evaluation: every
file of a run is named here and nowhere else.

    run/
      config.json       every option of the run and what it was trained on (RunRecord)
      gaussians.ply     3D-GS PLY + obj_feat_0..15
      classifier.pt     the 16 -> num_classes linear layer
      environment.pt    the learned background, when the run has one
      checkpoints/      resumable training state, step_NNNNNNN.pt
      metrics.json      the training curve
      labels.npz        per-Gaussian labels (`gsseg segment`)
      contributions.npz the contribution matrix they were chosen from (`gsseg segment`, `gsseg view`)
      evaluation.json   the scores of `gseval report`, for `gseval compare`
      edits/NAME/       one edit: gaussians.ply, renders/, video.mp4, edit.json
      .lock             held by the command writing the run (an OS file lock)
"""

from __future__ import annotations

import contextlib
import io
import json
from dataclasses import dataclass
from pathlib import Path

import torch

from dataset_tools.atomic import write_bytes_atomic
from dataset_tools.errors import InputError
from dataset_tools.locks import exclusive
from dataset_tools.names import plain_name


@dataclass(frozen=True)
class RunFolder:
    """The paths of one run folder (nothing is read or checked on construction)."""

    root: Path

    def __post_init__(self) -> None:
        object.__setattr__(self, "root", Path(self.root))

    @property
    def config(self) -> Path:
        return self.root / "config.json"

    @property
    def gaussians(self) -> Path:
        return self.root / "gaussians.ply"

    @property
    def classifier(self) -> Path:
        return self.root / "classifier.pt"

    @property
    def environment(self) -> Path:
        return self.root / "environment.pt"

    @property
    def checkpoints(self) -> Path:
        return self.root / "checkpoints"

    @property
    def metrics(self) -> Path:
        return self.root / "metrics.json"

    @property
    def labels(self) -> Path:
        return self.root / "labels.npz"

    @property
    def contributions(self) -> Path:
        return self.root / "contributions.npz"

    @property
    def evaluation(self) -> Path:
        return self.root / "evaluation.json"

    @property
    def edits(self) -> Path:
        return self.root / "edits"

    def edit(self, name: str) -> Path:
        """The folder of the edit called ``name``, which must be a plain folder name (an edit
        never reaches outside ``edits/``)."""
        return self.edits / plain_name(name, "--name")

    def checkpoint(self, step: int) -> Path:
        return self.checkpoints / f"step_{step:07d}.pt"

    def checkpoint_files(self) -> list[Path]:
        """The checkpoints, oldest first."""
        return sorted(self.checkpoints.glob("step_*.pt"))

    @property
    def finished(self) -> bool:
        """Whether training wrote the model files."""
        return all(p.is_file() for p in (self.config, self.gaussians, self.classifier))

    def lock(self) -> contextlib.AbstractContextManager[None]:
        """Hold the run's lock (:func:`dataset_tools.locks.exclusive` on ``.lock``) while
        writing the run; a second writer is refused in one sentence."""
        return exclusive(self.root / ".lock", self.root, "this run")

    def require_finished(self) -> None:
        for path in (self.config, self.gaussians, self.classifier):
            if not path.is_file():
                raise InputError(
                    f"{self.root} has no {path.name}; point to the --out folder of a finished `gsseg train`."
                )


def write_json(path: Path, data: dict) -> None:
    """Write ``data`` as indented JSON, atomically."""
    write_bytes_atomic(path, (json.dumps(data, indent=2) + "\n").encode())


def write_torch(path: Path, obj) -> None:
    """``torch.save`` to ``path``, atomically."""
    buf = io.BytesIO()
    torch.save(obj, buf)
    write_bytes_atomic(path, buf.getvalue())
