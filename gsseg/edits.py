"""Edits of a selected object: remove, extract, recolour; rendering of the result."""

from __future__ import annotations

import warnings
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import torch
from tqdm import tqdm

from dataset_tools.image_files import write_png
from dataset_tools.infra.atomic import atomic_directory, remove_stale_temporaries
from dataset_tools.infra.errors import InputError, OptionError, OutputExists
from dataset_tools.infra.names import plain_name
from dataset_tools.infra.overlap import refuse_overlap, scene_entries
from dataset_tools.scene import Scene
from gsseg.fill import fill_run_removal
from gsseg.fill_options import FillOptions
from gsseg.model.gaussians import Gaussians
from gsseg.model.ply import write_ply
from gsseg.model.sh import rgb_to_sh_dc
from gsseg.render import Backend, get_backend
from gsseg.run.folder import write_edit_record
from gsseg.run.loaded import Background, Run, load_run
from gsseg.segment.clicks import Click, ClickSelector, SceneHeld
from gsseg.segment.prompts import click_evidence, pick_object, point_evidence
from gsseg.segment.reassign import Segmentation
from gsseg.segment.segment_run import run_regions
from gsseg.segment.served import complete_selection

OPS = ("remove", "extract", "recolor")
COMPLETED_OPS = ("remove", "extract")  # they take the Gaussians that served the selection alone too
LUMA = torch.tensor([0.299, 0.587, 0.114])


def recolor(g: Gaussians, selected: torch.Tensor, rgb: tuple[float, float, float]) -> Gaussians:
    """Paint the selected Gaussians ``rgb`` (in [0, 1]) while keeping their shading: each one's
    new base colour is the target scaled by its luminance relative to the selection's mean,
    and its higher SH bands are scaled by the same luminance ratio as its DC."""
    out = Gaussians(**{k: v.clone() for k, v in g.tensors().items()})
    base = g.base_colours[selected]
    luma = base @ LUMA
    target = torch.tensor(rgb, dtype=base.dtype)
    shade = (luma / luma.mean().clamp_min(1e-6))[:, None]
    new = (target[None] * shade).clamp(0, 1)
    ratio = ((new @ LUMA) / luma.clamp_min(1e-6))[:, None, None]
    out.sh_dc[selected] = rgb_to_sh_dc(new)
    out.sh_rest[selected] = g.sh_rest[selected] * ratio
    return out


def edit_background(ops: Iterable[str]) -> Background:
    """What a model edited by ``ops`` is rendered over: white once an extraction has taken
    objects out of their scene (the learned environment is no part of them, and an exported
    object shows on any viewer's plain background), else the run's environment."""
    return "white" if "extract" in ops else "environment"


def check_edit(op: str, color: tuple | None) -> None:
    """Refuse an unknown ``op`` and a recolour without its ``color``."""
    if op not in OPS:
        raise InputError(f"unknown edit {op!r}; choose one of {', '.join(OPS)}.")
    if op == "recolor" and color is None:
        raise OptionError("{op} needs {color}, three values in 0..255.", op="recolor")


def apply_edit(g: Gaussians, selected: np.ndarray, op: str, rgb: tuple[float, float, float] | None = None) -> Gaussians:
    """A copy of ``g`` with ``op`` applied to the (N,) bool ``selected`` Gaussians."""
    check_edit(op, rgb)
    sel = torch.as_tensor(selected, dtype=torch.bool)
    if op == "remove":
        return g.select(~sel)
    if op == "extract":
        return g.select(sel)
    return recolor(g, sel, rgb)


@dataclass
class Selection:
    """Gaussians chosen by a prompt: ``mask`` (N,) bool, the ``object_id`` when it is one
    object, and ``name``, a folder-name-safe summary (the object, or the objects joined, with
    ``_split`` where an excluding click split them)."""

    mask: np.ndarray
    object_id: int | None
    name: str

    def main_label(self, labels: np.ndarray) -> int:
        """The label (not the background, 0) most of the selected Gaussians carry; 0 when none does."""
        held = np.bincount(labels[self.mask], minlength=256)[1:]
        return int(held.argmax() + 1) if held.any() else 0


def check_prompts(point, clicks: list[Click] | tuple[Click, ...], object_id: int | None) -> None:
    """Refuse prompts that do not make one selection: exactly one of an object ID or points
    and clicks, excluding clicks only after a point or a positive click, finite points."""
    positive = any(c.positive for c in clicks)
    if (object_id is not None) + (point is not None or positive) != 1:
        raise OptionError("give {object_id}, or {point} and/or {clicks} (with excluding clicks to split).")
    if object_id is not None and clicks:
        raise OptionError(
            "excluding clicks split the selection of {clicks} or {point}; give those instead of {object_id}."
        )
    if point is not None and not np.isfinite(np.asarray(point, float)).all():
        raise OptionError("{point}: give three finite coordinates.", point=tuple(point))


def select(
    run: Run,
    segmentation: Segmentation,
    scene: Scene,
    *,
    point=None,
    clicks: list[Click] | tuple[Click, ...] = (),
    object_id: int | None = None,
    k: int = 20,
    backend: str | Backend = "auto",
) -> Selection:
    """The Gaussians of an ``object_id``, of the object under a 3D ``point`` (its label), or of
    ``clicks`` (:class:`gsseg.segment.clicks.ClickSelector`, after the ``point`` where one is
    given too); clicks name views of ``scene``."""
    check_prompts(point, clicks, object_id)
    backend = get_backend(backend)
    means = run.gaussians.means.numpy()
    if object_id is None and not clicks:
        object_id = pick_object(means, segmentation.labels, np.asarray(point, float), k)
    if object_id is not None:
        mask = segmentation.selection(int(object_id))
        if not mask.any():
            raise InputError(
                f"object {object_id} of {run.folder.labels} holds no Gaussian; pick another object or "
                "segment the run again."
            )
        return Selection(mask, int(object_id), str(object_id))
    evidence = [point_evidence(run.gaussians, np.asarray(point, float), k)] if point is not None else []
    for c in clicks:
        view = scene.view(c.view)
        evidence.append(
            click_evidence(run.gaussians, view.camera, view.cam_from_world, c.u, c.v, c.positive, backend=backend)
        )
    selector = ClickSelector(run.gaussians, segmentation.labels, run_regions(run, scene.root, backend=backend))
    mask = selector.select(evidence)
    if selector.holds_the_scene(evidence):
        warnings.warn(
            SceneHeld(
                "the masks hold the clicked object and its surroundings as one region and do not say "
                "where it ends: the clicks do, for it (--click VIEW U V) and against what is not it "
                "(--exclude-click VIEW U V), in two views or more: a click reaches only what its view "
                "shows (docs/segmentation.md, Clicks)."
            ),
            stacklevel=2,
        )
    objects = sorted(set(np.unique(segmentation.labels[mask]).tolist()))
    split = any(not c.positive for c in clicks)
    return Selection(mask, None, "click_" + "+".join(map(str, objects)) + ("_split" if split else ""))


def edit_run(
    run_dir: Path | str,
    op: str,
    *,
    color: tuple[int, int, int] | None = None,
    name: str | None = None,
    **options,
) -> Path:
    """Select Gaussians (:func:`select`), with those that served the selection alone for a
    removal or an extraction (:mod:`gsseg.segment.served`), apply ``op`` and write ``RUN/edits/NAME/``:
    ``gaussians.ply``, ``renders/<view>.png`` of the scene's ``split`` views, ``video.mp4`` of
    those renders, and ``edit.json``. ``fill``: a removal fills what no training view saw
    behind the object with these options (:mod:`gsseg.fill`; None: the removal alone).
    ``options``: the prompt and the rest of :func:`edit_runs`' keywords, whose defaults are the defaults here."""
    return edit_runs(run_dir, {op: color}, names=None if name is None else {op: name}, **options)[1][0]


def edit_runs(
    run_dir: Path | str,
    ops: dict[str, tuple[int, int, int] | None],
    *,
    names: dict[str, str] | None = None,
    point=None,
    clicks: list[Click] | tuple[Click, ...] = (),
    object_id: int | None = None,
    scene_dir: Path | str | None = None,
    split: str = "test",
    k: int = 20,
    fps: int = 8,
    fill: FillOptions | None = FillOptions(),
    backend: str | Backend = "auto",
    overwrite: bool = False,
    other_scene: bool = False,
    progress: bool = True,
) -> tuple[Selection, list[Path]]:
    """:func:`edit_run` of each op of ``ops`` (op: its colour, None but for a recolour) on one
    selection, made once; ``names``: the folder name of an op (default: ``<op>_<selection>``).
    Returns the selection and the edit folders in the order of ``ops``."""
    check_prompts(point, clicks, object_id)
    names = names or {}
    for op, color in ops.items():
        check_edit(op, color)
        if color is not None and not all(0 <= c <= 255 for c in color):
            raise OptionError("{color}: give three values in 0..255.", color=tuple(color))
        if op in names:
            plain_name(names[op], "name")
    run = load_run(run_dir, other_scene=other_scene)
    segmentation = run.labels()
    backend = get_backend(backend)
    scene = run.scene(scene_dir)
    chosen = select(run, segmentation, scene, point=point, clicks=clicks, object_id=object_id, k=k, backend=backend)
    served = None
    if any(op in COMPLETED_OPS for op in ops):
        served = complete_selection(run.gaussians, chosen.mask, scene.split("train"), backend=backend)
    record = {
        "object_id": chosen.object_id,
        "point": None if point is None else np.asarray(point).tolist(),
        "clicks": [{"view": c.view, "u": c.u, "v": c.v, "positive": c.positive} for c in clicks],
        "selected_gaussians": int(chosen.mask.sum()),
        "labels": segmentation.settings(),
    }
    written = []
    for op, color in ops.items():
        mask = served.mask if op in COMPLETED_OPS else chosen.mask
        filled = None
        if op == "remove" and fill is not None:
            filled = fill_run_removal(run, mask, scene.split("train"), options=fill, backend=backend, progress=progress)
            edited = filled.gaussians
        else:
            edited = apply_edit(run.gaussians, mask, op, None if color is None else tuple(c / 255 for c in color))
        op_record = {
            "op": op,
            **record,
            "color": color,
            **(
                {"served_alone": served.added, "ghost_share": [served.ghost_before, served.ghost_after]}
                if op in COMPLETED_OPS
                else {}
            ),
            **({} if op != "remove" else {"removal_fill": None if filled is None else filled.record()}),
        }
        written.append(
            write_edit(
                run,
                edited,
                run.folder.edit(names.get(op) or f"{op}_{chosen.name}"),
                op_record,
                scene=scene,
                background=edit_background([op]),
                split=split,
                fps=fps,
                backend=backend,
                overwrite=overwrite,
                progress=progress,
            )
        )
    return chosen, written


def write_edit(
    run: Run,
    edited: Gaussians,
    out: Path,
    record: dict,
    *,
    scene: Scene,
    background: Background = "environment",
    split: str = "test",
    fps: int = 8,
    backend: str | Backend = "auto",
    overwrite: bool = False,
    progress: bool = True,
) -> Path:
    """Write the edit folder ``out`` (inside ``RUN/edits/``) of the ``edited`` model:
    ``gaussians.ply``, ``renders/<view>.png`` of ``scene``'s ``split`` views over
    ``background`` (:func:`edit_background`), ``video.mp4`` and ``edit.json`` (``record``);
    whole or not at all."""
    refuse_overlap(out, scene_entries(scene.root))
    remove_stale_temporaries(out.parent / "*")  # what killed edits left in RUN/edits/
    if out.exists() and not overwrite:
        raise OutputExists(out, " or choose another {name}")
    with run.folder.lock(), atomic_directory(out, overwrite=overwrite) as tmp:
        write_ply(edited, tmp / "gaussians.ply")
        frames = []
        for view in tqdm(scene.split(split), desc="rendering edit", unit="view", disable=not progress):
            frame = run.render_rgb(view, gaussians=edited, background=background, backend=backend)
            write_png(tmp / "renders" / f"{view.stem}.png", frame)
            frames.append(frame)
        _write_video(tmp / "video.mp4", frames, fps)
        write_edit_record(tmp, record)
    return out


def _write_video(path: Path, frames: list[np.ndarray], fps: int) -> None:
    """An MP4 of ``frames`` (H, W, 3) uint8; frames of other sizes (the undistorted views of one
    capture differ by a few pixels) are padded with black to the largest."""
    if not frames:
        return
    h = max(f.shape[0] for f in frames)
    w = max(f.shape[1] for f in frames)
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), fps, (w, h))
    if not writer.isOpened():
        raise InputError(f"{path}: OpenCV cannot write an mp4v video here; install an OpenCV build with video I/O.")
    for f in frames:
        padded = np.zeros((h, w, 3), np.uint8)
        padded[: f.shape[0], : f.shape[1]] = f
        writer.write(cv2.cvtColor(padded, cv2.COLOR_RGB2BGR))
    writer.release()
