"""``gsseg export``: a run's model, or one object of it, in files that other 3D-GS tools open.

Two formats:

- ``ply``: the 3D-GS PLY of :mod:`gsseg.model.ply` plus a uchar ``label`` per Gaussian (its object
  in ``labels.npz``; 3D-GS viewers ignore the extra properties).
- ``splat``: the 32-byte record per Gaussian that web splat viewers load: position (3 x
  float32), scale (3 x float32, linear), colour and opacity (4 x uint8), rotation (4 x uint8,
  the normalised (w, x, y, z) quaternion mapped from [-1, 1] to [0, 255]); records sorted by
  volume times opacity, largest first. Degree-0 colour only: the format has no SH bands.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from dataset_tools.cameras import CameraPose, PinholeCamera
from dataset_tools.infra.atomic import write_bytes_atomic
from dataset_tools.infra.errors import InputError, OptionError, OutputExists
from dataset_tools.infra.overlap import refuse_overlap, run_inputs
from gsseg.edits import check_prompts, edit_background, select
from gsseg.model.environment import environment_shell, shell_radius, shell_spacing
from gsseg.model.gaussians import Gaussians
from gsseg.model.ply import read_ply, write_ply
from gsseg.run.folder import read_edit_record
from gsseg.run.loaded import Run, load_run
from gsseg.segment.clicks import Click
from gsseg.segment.served import complete_selection

FORMATS = ("ply", "splat")
SPLAT_RECORD = np.dtype([("position", "<f4", 3), ("scale", "<f4", 3), ("rgba", "u1", 4), ("rotation", "u1", 4)])


def splat_records(g: Gaussians) -> np.ndarray:
    """(N,) :data:`SPLAT_RECORD` of ``g``, largest volume x opacity first."""
    with torch.no_grad():
        scales = g.scales.cpu().numpy()
        opacity = g.opacities.cpu().numpy()
        rgb = g.base_colours.cpu().numpy()
        quats = torch.nn.functional.normalize(g.quats, dim=-1).cpu().numpy()
    order = np.argsort(-(scales.prod(1) * opacity), kind="stable")
    out = np.empty(len(g), SPLAT_RECORD)
    out["position"] = g.means.detach().cpu().numpy()[order]
    out["scale"] = scales[order]
    out["rgba"] = np.round(np.concatenate([rgb, opacity[:, None]], 1)[order] * 255)
    out["rotation"] = np.clip(np.round(quats[order] * 128 + 128), 0, 255)
    return out


def read_splat(path: Path | str) -> np.ndarray:
    """The (N,) :data:`SPLAT_RECORD` records of a ``.splat`` file."""
    data = Path(path).read_bytes()
    if len(data) % SPLAT_RECORD.itemsize:
        raise InputError(f"{path}: {len(data)} bytes is not a whole number of 32-byte splat records; export it again.")
    return np.frombuffer(data, SPLAT_RECORD)


def shell_for(run: Run) -> Gaussians:
    """The run's environment as a shell of Gaussians (:func:`gsseg.model.environment.environment_shell`)
    about the cameras' mean centre, :func:`gsseg.model.environment.shell_radius` away."""
    recorded = run.record.scene_fingerprint
    if recorded is not None:
        cameras = [
            CameraPose(PinholeCamera(*v["size"], *v["camera"]), np.asarray(v["pose"]).reshape(3, 4))
            for v in recorded["views"].values()
        ]
    else:  # runs from before the fingerprint: their scene
        cameras = run.scene().views
    center = np.mean([c.center for c in cameras], axis=0)
    focal = max(max(c.camera.fx, c.camera.fy) for c in cameras)
    return environment_shell(run.environment, center, shell_radius(run.record.extent), shell_spacing(focal))


def export_run(
    run_dir: Path | str,
    out: Path | str,
    *,
    object_id: int | None = None,
    point=None,
    clicks: list[Click] | tuple[Click, ...] = (),
    edit: str | None = None,
    scene_dir: Path | str | None = None,
    fmt: str | None = None,
    environment: bool | None = None,
    overwrite: bool = False,
) -> Path:
    """Write a run's model (or the Gaussians of ``object_id`` alone, or of the selection of a
    ``point`` and ``clicks`` in views of the run's scene or ``scene_dir``: :func:`gsseg.edits.select`;
    or the model of the edit ``RUN/edits/EDIT``, a removal with its fill) to ``out`` as
    ``fmt`` (default: from the suffix of ``out``, ``.ply`` or ``.splat``), atomically; an
    existing ``out`` is replaced only with ``overwrite``, and never one inside the run folder.

    ``environment``: add the run's learned background as a shell of Gaussians (label 0), so
    that a renderer that knows nothing of it shows what ``gsseg render`` shows; None: for the
    whole model of a run that has one and for its edits but extractions, not for an object or
    a selection."""
    out = Path(out)
    refuse_overlap(out, run_inputs(run_dir))
    if out.is_dir():
        raise InputError(f"{out} is a folder; give a file name for the export.")
    fmt = fmt or out.suffix.lstrip(".").lower()
    if fmt not in FORMATS:
        raise OptionError("cannot tell the format; end the name in .ply or .splat, or pass {fmt}.", file=out)
    run = load_run(run_dir)
    refuse_overlap(out, run.inputs())  # nor anything of the scene it was trained on
    if out.exists() and not overwrite:
        raise OutputExists(out, " or choose another {out}")
    if environment and run.environment is None:
        raise InputError(
            f"{run.root} was trained without an environment (black behind the Gaussians); export it without one."
        )
    g = run.gaussians
    prompted = point is not None or bool(clicks)
    if edit is not None:
        if prompted or object_id is not None:
            raise OptionError("{edit} exports an edit's whole model; give it without {object} or clicks.")
        return _export_edit(run, run.folder.edit(edit), out, fmt, environment)
    if prompted:
        check_prompts(point, clicks, object_id)
    segmentation = run.labels() if object_id is not None or prompted or run.folder.labels.is_file() else None
    labels = None if segmentation is None else segmentation.labels
    if object_id is not None or prompted:
        if object_id is not None:
            keep = labels == object_id
            if not keep.any():
                raise InputError(
                    f"object {object_id} holds no Gaussian in {run.folder.labels}; pick one of "
                    f"{sorted(set(np.unique(labels).tolist()) - {0})}."
                )
        else:
            keep = select(run, segmentation, run.scene(scene_dir), point=point, clicks=clicks).mask
        if object_id != 0:  # an object, as an extraction takes it: with what served it alone
            keep = complete_selection(g, keep, run.scene(scene_dir).split("train")).mask
        g, labels = g.select(torch.from_numpy(keep)), labels[keep]
    whole = object_id is None and not prompted
    if environment or (environment is None and whole and run.environment is not None):
        shell = shell_for(run)
        g = Gaussians.concat(g, shell)
        labels = None if labels is None else np.concatenate([labels, np.zeros(len(shell), labels.dtype)])
    return _write(g, labels, out, fmt)


def _export_edit(run: Run, edit_dir: Path, out: Path, fmt: str, environment: bool | None) -> Path:
    """The model of ``edit_dir`` (``gsseg edit``'s or the viewer's ``gaussians.ply``), with the
    run's environment unless told otherwise or an extraction took the object out of it."""
    if not (edit_dir / "gaussians.ply").is_file():
        raise InputError(f"{edit_dir} holds no edit; make it with `gsseg edit` or the viewer's Save first.")
    record = read_edit_record(edit_dir)
    ops = [s["op"] for s in record.get("steps", [record])]
    g = read_ply(edit_dir / "gaussians.ply")
    if environment is None:
        environment = run.environment is not None and edit_background(ops) == "environment"
    if environment:
        g = Gaussians.concat(g, shell_for(run))
    return _write(g, None, out, fmt)


def _write(g: Gaussians, labels: np.ndarray | None, out: Path, fmt: str) -> Path:
    """``g`` (with ``labels``, (N,) uint8, in a PLY) to ``out`` as ``fmt``."""
    if fmt == "ply":
        return write_ply(g, out, labels=labels)
    write_bytes_atomic(out, splat_records(g).tobytes())
    return out
