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
      regions.npz       each Gaussian's weight in every mask region of every view, the evidence
                        clicks select with (`gsseg segment`, or the first click)
      evaluation.json   the scores of `gseval report`, for `gseval compare`
      edits/NAME/       one edit: gaussians.ply, renders/, video.mp4, edit.json
      .lock             held by the command writing the run (an OS file lock)

Each file is read and written here alone (``RunFolder.read_*`` / ``write_*``): the JSON files
and the npz files carry ``format_version`` (:data:`FORMAT_VERSIONS`); a file without one is
from before versions were recorded and reads as version 0; a file from a newer version is
refused in one sentence.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import zipfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TypeVar

import numpy as np
import scipy.sparse as sp
import torch

from dataset_tools.infra.atomic import write_bytes_atomic
from dataset_tools.infra.errors import InputError
from dataset_tools.infra.locks import exclusive
from dataset_tools.infra.names import plain_name
from gsseg.model.environment import Environment
from gsseg.model.gaussians import Gaussians, make_classifier
from gsseg.model.ply import read_ply, write_ply
from gsseg.render.contributions import Contributions, RegionWeights
from gsseg.run.record import RunRecord
from gsseg.segment.reassign import Segmentation

FORMAT_VERSIONS = {
    "config.json": 1,
    "metrics.json": 1,
    "labels.npz": 1,
    "contributions.npz": 1,
    "regions.npz": 1,
    "evaluation.json": 1,
    "edit.json": 1,
}
HISTORY_KEYS = ("step", "psnr")  # what every logged step of the training curve holds, at least
T = TypeVar("T")
DAMAGED = (OSError, ValueError, KeyError, TypeError, AttributeError, EOFError, zipfile.BadZipFile)


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
    def regions(self) -> Path:
        return self.root / "regions.npz"

    @property
    def evaluation(self) -> Path:
        return self.root / "evaluation.json"

    @property
    def edits(self) -> Path:
        return self.root / "edits"

    def edit(self, name: str) -> Path:
        """The folder of the edit called ``name``, which must be a plain folder name (an edit
        never reaches outside ``edits/``)."""
        return self.edits / plain_name(name, "name")

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
        """Hold the run's lock (:func:`dataset_tools.infra.locks.exclusive` on ``.lock``) while
        writing the run; a second writer is refused in one sentence."""
        return exclusive(self.root / ".lock", self.root, "this run")

    def require_finished(self) -> None:
        for path in (self.config, self.gaussians, self.classifier):
            if not path.is_file():
                raise InputError(f"{self.root} has no {path.name}; point to the folder of a finished `gsseg train`.")

    # config.json
    def read_config(self) -> RunRecord:
        """The run's options and what it was trained on; a damaged file is refused."""
        try:
            return RunRecord.from_json(_read_json(self.config))
        except DAMAGED as e:
            raise damaged(self.config, e) from None

    def write_config(self, record: RunRecord) -> None:
        _write_json(self.config, record.to_json())

    # gaussians.ply, classifier.pt, environment.pt, metrics.json: the finished model
    def read_gaussians(self) -> Gaussians:
        return read_ply(self.gaussians)

    def model_fingerprint(self) -> str:
        """A digest of gaussians.ply, which names the model that labels and contributions were
        computed for."""
        return hashlib.sha256(self.gaussians.read_bytes()).hexdigest()[:16]

    def read_classifier(self) -> torch.nn.Linear:
        try:
            state = torch.load(self.classifier, map_location="cpu", weights_only=True)
            classifier = make_classifier(state["weight"].shape[0])
            classifier.load_state_dict(state)
            return classifier
        except Exception as e:  # truncated, foreign or unpicklable: torch raises many types
            raise damaged(self.classifier, e) from None

    def read_environment(self) -> Environment | None:
        """The learned background, None when the run has none."""
        if not self.environment.is_file():
            return None
        try:
            return Environment.from_state(torch.load(self.environment, map_location="cpu", weights_only=True))
        except Exception as e:  # as above
            raise damaged(self.environment, e) from None

    def write_model(
        self,
        gaussians: Gaussians,
        classifier: torch.nn.Linear,
        environment: Environment | None,
        steps: int,
        history: list[dict],
    ) -> None:
        """Write the finished model: gaussians.ply, classifier.pt, environment.pt (when there is
        one) and the training curve ``history`` in metrics.json."""
        write_ply(gaussians.detach().to("cpu"), self.gaussians)
        write_torch(self.classifier, {k: v.cpu() for k, v in classifier.state_dict().items()})
        if environment is not None:
            write_torch(self.environment, {k: v.cpu() for k, v in environment.state_dict().items()})
        _write_json(self.metrics, {"train": {"steps": steps, "gaussians": len(gaussians), "history": history}})

    def read_history(self) -> list[dict]:
        """The training curve of metrics.json (one dict per logged step), empty when the file is
        missing."""
        if not self.metrics.is_file():
            return []
        try:
            history = list(_read_json(self.metrics).get("train", {}).get("history", []))
            for entry in history:
                if not (isinstance(entry, dict) and all(isinstance(entry.get(k), (int, float)) for k in HISTORY_KEYS)):
                    raise ValueError(f"a step without {' and '.join(HISTORY_KEYS)}")
            return history
        except DAMAGED as e:
            raise damaged(self.metrics, e) from None

    # labels.npz, contributions.npz: `gsseg segment`
    def read_labels(self) -> Segmentation:
        """The labels of ``gsseg segment``; missing or damaged files are refused."""
        if not self.labels.is_file():
            raise InputError(f"{self.labels} does not exist; run `gsseg segment` on the run first.")
        return _read_npz(
            self.labels,
            "labels",
            "run `gsseg segment` on the run again",
            lambda f: Segmentation(
                labels=f["labels"],
                objects=f["objects"],
                selections=f["selections"],
                method=str(f["method"]),
                mode=str(f["mode"]),
                gamma_p=float(f["gamma_p"]),
                model=str(f["model"]) if "model" in f else "",
                smooth=int(f["smooth"]) if "smooth" in f else 0,
                fill=bool(f["fill"]) if "fill" in f else False,
            ),
        )

    def write_labels(self, segmentation: Segmentation) -> None:
        s = segmentation
        _write_npz(
            self.labels,
            compressed=True,
            labels=s.labels,
            objects=s.objects,
            selections=s.selections,
            method=s.method,
            mode=s.mode,
            gamma_p=s.gamma_p,
            model=s.model,
            smooth=s.smooth,
            fill=s.fill,
            gaussians=len(s.labels),
        )

    def read_contributions(self) -> Contributions | None:
        """The contribution matrix ``gsseg segment`` wrote, None when there is none."""
        if not self.contributions.is_file():
            return None
        return _read_npz(
            self.contributions,
            "contribution cache",
            "delete it and run `gsseg segment` again",
            lambda f: Contributions(
                labels=f["labels"],
                weights=torch.from_numpy(f["weights"]),
                model=str(f["model"]),
                masks=str(f["masks"]) if "masks" in f else "",
            ),
        )

    def write_contributions(self, contributions: Contributions) -> None:
        c = contributions
        _write_npz(self.contributions, labels=c.labels, weights=c.weights.numpy(), model=c.model, masks=c.masks)

    def read_regions(self) -> RegionWeights | None:
        """The region weights ``gsseg segment`` wrote, None when there are none."""
        if not self.regions.is_file():
            return None
        return _read_npz(
            self.regions,
            "region weights",
            "delete the file and run `gsseg segment` again",
            lambda f: RegionWeights(
                sp.csr_matrix((f["data"], f["indices"], f["indptr"]), shape=tuple(int(n) for n in f["shape"])),
                f["view"],
                f["label"],
                f["layer"],
                tuple(str(name) for name in f["layers"]),
                str(f["model"]),
            ),
        )

    def write_regions(self, regions: RegionWeights) -> None:
        m = regions.matrix.tocsr()
        _write_npz(
            self.regions,
            compressed=True,
            data=m.data.astype(np.float32),
            indices=m.indices.astype(np.int32),
            indptr=m.indptr.astype(np.int64),
            shape=np.array(m.shape),
            view=regions.view,
            label=regions.label,
            layer=regions.layer,
            layers=np.array(regions.layers),
            model=regions.model,
        )

    # evaluation.json: `gseval report`
    def read_evaluation(self) -> dict:
        """The scores ``gseval report`` wrote (``eval.evaluate.Evaluation.to_json``)."""
        if not self.evaluation.is_file():
            raise InputError(
                f"{self.evaluation}: missing; run `gseval report {self.root} --scene SCENE --out DIR` first."
            )
        try:
            return _read_json(self.evaluation)
        except DAMAGED as e:
            raise InputError(f"{self.evaluation}: damaged ({e}); run `gseval report` on the run again.") from None

    def write_evaluation(self, data: dict) -> None:
        _write_json(self.evaluation, data)


def write_edit_record(edit_dir: Path, record: dict) -> None:
    """``edit_dir/edit.json``: what an edit did (object, operation, the labels' settings)."""
    _write_json(edit_dir / "edit.json", record)


def read_edit_record(edit_dir: Path) -> dict:
    path = edit_dir / "edit.json"
    try:
        return _read_json(path)
    except DAMAGED as e:
        raise damaged(path, e) from None


def damaged(path: Path, e: Exception) -> InputError:
    """The refusal of a damaged run file: what went wrong in one line, without the library's
    advice (PyTorch's to load the file unsafely)."""
    first = str(e).splitlines()[0] if str(e) else ""
    what = type(e).__name__ + (f": {first}" if first and "weights_only" not in first else "")
    return InputError(f"{path}: damaged run file ({what}); restore it or train the run again.")


def _read_npz(path: Path, what: str, fix: str, build: Callable[[np.lib.npyio.NpzFile], T]) -> T:
    """``build`` of the arrays of the run file ``path`` once its format version is checked; a
    damaged file is one error naming ``what`` it holds and the ``fix``."""
    try:
        with np.load(path, allow_pickle=False) as f:
            _check_version(path, f)
            return build(f)
    except DAMAGED as e:
        raise InputError(f"{path}: damaged {what} ({e}); {fix}.") from None


def _check_version(path: Path, data) -> None:
    """Refuse ``path`` when ``data`` (its JSON object or npz arrays) carries a format version
    newer than this code reads; none is version 0."""
    version = int(data["format_version"]) if "format_version" in data else 0
    known = FORMAT_VERSIONS[path.name]
    if version > known:
        raise InputError(
            f"{path}: format version {version}, newer than this gsseg reads ({known}); update gsseg to read it."
        )


def _read_json(path: Path) -> dict:
    data = json.loads(path.read_text())
    if not isinstance(data, dict):
        raise ValueError("not a JSON object")
    _check_version(path, data)
    data.pop("format_version", None)
    return data


def _write_json(path: Path, data: dict) -> None:
    write_json(path, {"format_version": FORMAT_VERSIONS[path.name], **data})


def _write_npz(path: Path, *, compressed: bool = False, **arrays) -> None:
    buf = io.BytesIO()
    (np.savez_compressed if compressed else np.savez)(buf, format_version=FORMAT_VERSIONS[path.name], **arrays)
    write_bytes_atomic(path, buf.getvalue())


def write_json(path: Path, data: dict) -> None:
    """Write ``data`` as indented JSON, atomically."""
    write_bytes_atomic(path, (json.dumps(data, indent=2) + "\n").encode())


def write_torch(path: Path, obj) -> None:
    """``torch.save`` to ``path``, atomically."""
    buf = io.BytesIO()
    torch.save(obj, buf)
    write_bytes_atomic(path, buf.getvalue())
