"""What ``gsseg view`` does, without the browser: the model as edited so far, its labels, the
selected object, the frames it renders, relabelling from the cached contribution matrix, and
saving an edit folder exactly as ``gsseg edit`` writes one."""

from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import torch
from scipy.spatial.transform import Rotation

from dataset_tools.cameras import PinholeCamera
from dataset_tools.image_files import label_palette
from dataset_tools.infra.errors import InputError
from gsseg.edits import COMPLETED_OPS, apply_edit, check_edit, edit_background, write_edit
from gsseg.fill import Filled, fill_run_removal
from gsseg.fill_options import FillOptions
from gsseg.model.gaussians import Gaussians
from gsseg.model.sh import rgb_to_sh_dc
from gsseg.render import get_backend
from gsseg.render.contributions import Contributions
from gsseg.run.loaded import Run
from gsseg.segment.clicks import ClickEvidence, ClickSelector
from gsseg.segment.label_options import LabelOptions
from gsseg.segment.prompts import click_evidence
from gsseg.segment.reassign import Segmentation
from gsseg.segment.segment_run import label_gaussians, mask_contributions, run_regions
from gsseg.segment.served import complete_selection

HIGHLIGHT = (1.0, 0.85, 0.0)  # the selected object is drawn halfway towards this colour


@dataclass(frozen=True)
class ViewCamera:
    """A pinhole camera and its (3, 4) world-to-camera pose: what the browser looks through."""

    camera: PinholeCamera
    cam_from_world: np.ndarray


def browser_camera(
    wxyz: np.ndarray, position: np.ndarray, fov_y: float, width: int, height: int, *, max_size: int, near: float
) -> ViewCamera:
    """The pinhole view of viser's camera, at most ``max_size`` pixels on its long side.

    Args:
        wxyz: (4,) the camera-to-world rotation as a (w, x, y, z) quaternion, OpenCV axes
            (x right, y down, z forward), as viser reports it.
        position: (3,) the camera centre in world coordinates.
        fov_y: the vertical field of view in radians.
        width, height: the browser canvas in pixels.
    """
    scale = min(1.0, max_size / max(width, height))
    w, h = max(1, round(width * scale)), max(1, round(height * scale))
    f = h / 2 / math.tan(fov_y / 2)
    world_from_cam = Rotation.from_quat(np.asarray(wxyz, np.float64), scalar_first=True).as_matrix()
    rotation = world_from_cam.T
    pose = np.concatenate([rotation, -rotation @ np.asarray(position, np.float64)[:, None]], 1)
    return ViewCamera(PinholeCamera(w, h, f, f, w / 2, h / 2, near), pose)


@dataclass(frozen=True)
class EditStep:
    """One edit of the viewer: ``op`` on object ``object_id`` (``color`` R G B for recolour),
    or on the (N,) bool ``selection`` of the model the step was applied to where there is one
    (a selection made by clicks, ``object_id`` None; a removal or extraction, with what served
    the selection alone)."""

    op: str
    object_id: int | None
    color: tuple[int, int, int] | None = None
    selection: np.ndarray | None = field(default=None, compare=False, repr=False)


class ViewerSession:
    """The state of one viewer (shared by every browser tab open on it); thread-safe.

    Objects are selected and edited through the labels of ``RUN/labels.npz``; without it the
    model is shown but ``segments_missing`` says how to make labels and selection is off.
    A removal is filled with the options ``fill`` (:mod:`gsseg.fill`), as ``gsseg edit`` fills it.
    """

    def __init__(
        self,
        run: Run,
        *,
        scene_dir: Path | str | None = None,
        masks: str | None = None,
        backend: str = "auto",
        k: int = 20,
        fill: FillOptions = FillOptions(),
    ) -> None:
        self.run = run
        self.fill_options = fill
        self.scene_dir = scene_dir
        self.masks = masks or run.masks
        self.backend = get_backend(backend)
        self.k = k
        self.scene = run.scene(scene_dir)
        self.segmentation: Segmentation | None = run.labels() if run.folder.labels.is_file() else None
        self.steps: list[EditStep] = []
        self.selected: int | None = None  # an object chosen by its ID
        self.clicks: list[ClickEvidence] = []  # the clicks selecting now, in order
        self._click_selection: np.ndarray | None = None  # (N,) bool: the selection the clicks made
        self.show_segments = False
        self._contributions: Contributions | None = None
        self._current: tuple[Gaussians, Segmentation | None, np.ndarray] | None = None
        self._selector: ClickSelector | None = None
        self._fill: tuple[list[EditStep], Filled] | None = None  # the fill of these steps' removals
        self._lock = threading.RLock()

    @property
    def segments_missing(self) -> str | None:
        """The sentence shown while there are no labels, None once there are."""
        if self.segmentation is not None:
            return None
        return (
            f"{self.run.folder.labels} does not exist: segments are off. Run `gsseg segment {self.run.root}` "
            "and open the viewer again to select and edit objects."
        )

    def current(self) -> tuple[Gaussians, Segmentation | None]:
        """The model after every edit step, and its labels (None without labels)."""
        g, seg, _ = self._edited()
        return g, seg

    def _edited(self) -> tuple[Gaussians, Segmentation | None, np.ndarray]:
        """:meth:`current`, and which of the run's Gaussians (N,) bool it holds."""
        with self._lock:
            if self._current is None:
                g, seg = self.run.gaussians, self.segmentation
                kept = np.ones(len(g), bool)
                for step in self.steps:
                    selected = step.selection if step.selection is not None else seg.selection(step.object_id)
                    rgb = None if step.color is None else tuple(c / 255 for c in step.color)
                    g = apply_edit(g, selected, step.op, rgb)
                    if step.op != "recolor":
                        left = ~selected if step.op == "remove" else selected
                        seg = seg.subset(left)
                        kept[np.flatnonzero(kept)[~left]] = False
                self._current = g, seg, kept
                self._selector = None
            return self._current

    def fill(self, wait: bool = True) -> Filled | None:
        """The fill of what the removals took (:mod:`gsseg.fill`, as ``gsseg edit`` fills a
        removal), for the current steps: None where they remove nothing or extract (an
        extracted object shows alone). ``wait``: compute it when it is not there yet (the
        viewer does it in a thread); else None until it is ready. :meth:`frame` shows it then."""
        with self._lock:
            steps = list(self.steps)
            if self._fill is not None and self._fill[0] == steps:
                return self._fill[1]
            if not wait or not any(s.op == "remove" for s in steps) or any(s.op == "extract" for s in steps):
                return None
            g, _, kept = self._edited()
        whole = Gaussians(**{n: t.clone() for n, t in self.run.gaussians.tensors().items()})
        for name, t in whole.tensors().items():
            t[torch.from_numpy(kept)] = getattr(g, name)  # recolours kept
        filled = fill_run_removal(
            self.run,
            ~kept,
            self.scene.split("train"),
            gaussians=whole,
            options=self.fill_options,
            backend=self.backend,
            progress=False,
        )
        with self._lock:
            if self.steps == steps:
                self._fill = steps, filled
        return filled

    def _click_selector(self) -> ClickSelector:
        """The click rule of ``gsseg edit`` for the current model (built at the first click)."""
        g, seg, kept = self._edited()
        if self._selector is None:
            regions = run_regions(self.run, self.scene_dir, backend=self.backend)
            self._selector = ClickSelector(g, seg.labels, regions if kept.all() else regions.subset(kept))
        return self._selector

    def objects(self) -> list[tuple[int, int]]:
        """(object ID, Gaussian count) of every object of the current model."""
        _, seg = self.current()
        if seg is None:
            return []
        return [(int(o), int(s.sum())) for o, s in zip(seg.objects, seg.selections) if s.any()]

    def select_at(self, view: ViewCamera, u: float, v: float, mode: str = "select") -> np.ndarray:
        """Select with a click at pixel (u, v) of ``view`` by the rule of ``gsseg edit --click``
        (:class:`gsseg.segment.clicks.ClickSelector`): ``select`` (a click) starts a selection,
        ``add`` (ctrl-click) adds what is there, ``exclude`` (shift-click) takes it out. Each
        click changes the selection the clicks before it made. Returns the (N,) bool
        selection of the current model."""
        if mode not in ("select", "add", "exclude"):
            raise ValueError(f"unknown selection mode {mode!r}")
        g, seg = self.current()
        if seg is None:
            raise InputError(self.segments_missing)
        seen = click_evidence(g, view.camera, view.cam_from_world, u, v, backend=self.backend)
        with self._lock:
            if mode == "exclude" and not self.clicks:
                raise InputError("shift-click takes a part out of a selection: click an object first.")
            restart = mode == "select" or not self.clicks
            click = replace(seen, positive=restart or mode == "add")
            clicks = [click] if restart else [*self.clicks, click]
            selector = self._click_selector()
            self._click_selection = selector.cut(clicks, None if restart else self._click_selection)
            self.clicks, self.selected = clicks, None
            return self._click_selection

    def scene_held(self) -> bool:
        """Whether the clicks selecting now, none of them against, began on an object the masks
        hold as one region with its surroundings (:meth:`ClickSelector.holds_the_scene`): the
        clicks alone say where the object ends."""
        with self._lock:
            return bool(self.clicks) and self._click_selector().holds_the_scene(self.clicks)

    def selection(self) -> np.ndarray | None:
        """(N,) bool: the Gaussians of the current model selected now, or None."""
        g, seg = self.current()
        with self._lock:
            if self._click_selection is not None:
                return self._click_selection
            if self.selected is None or seg is None or self.selected not in seg.objects:
                return None
            return seg.selection(self.selected)

    def _forget_clicks(self) -> None:
        self.clicks, self._click_selection = [], None

    def edit(self, op: str, color: tuple[int, int, int] | None = None) -> EditStep:
        """Apply ``op`` to the selected object; the step is kept for :meth:`undo` and :meth:`save`."""
        check_edit(op, color)
        with self._lock:
            selection = self.selection()
            if selection is None:
                raise InputError("select an object first: click on it in the scene.")
            if op in COMPLETED_OPS:  # as gsseg edit: with what served the selection alone
                selection = complete_selection(
                    self.current()[0], selection, self.scene.split("train"), backend=self.backend
                ).mask
            step = EditStep(
                op,
                self.selected,
                None if color is None else tuple(int(c) for c in color),
                selection.copy() if self.selected is None or op in COMPLETED_OPS else None,
            )
            self.steps.append(step)
            self._current = None
            if op == "remove":
                self.selected = None
                self._forget_clicks()
            elif op == "extract" and self._click_selection is not None:
                self._click_selection = np.ones(int(selection.sum()), bool)  # the whole model is the selection
                self.clicks = []  # they saw the model before the extraction; the next click starts anew
            return step

    def undo(self) -> EditStep | None:
        """Take back the last edit step (None when there is none)."""
        with self._lock:
            if not self.steps:
                return None
            self._current = None
            self._forget_clicks()
            return self.steps.pop()

    def relabel(self, method: str, gamma_p: float) -> float:
        """Reassign every Gaussian's label with ``method`` and ``gamma_p`` from the contribution
        matrix (read from ``RUN/contributions.npz``, computed from the masks and written there
        when absent), with the 3D regularisations of the labels shown. The seconds the
        reassignment took, the matrix aside."""
        shown = self.segmentation
        options = LabelOptions(
            method=method, gamma_p=gamma_p, smooth=shown.smooth if shown else 0, fill=shown.fill if shown else False
        )
        contributions = self.contributions()
        start = time.perf_counter()
        segmentation = label_gaussians(self.run, contributions, options)
        seconds = time.perf_counter() - start
        with self._lock:
            self.segmentation = segmentation
            self._current = None
            self._forget_clicks()
            if self.selected is not None and self.selected not in segmentation.objects:
                self.selected = None
        return seconds

    def contributions(self) -> Contributions:
        """The run's contribution matrix: the cached one when it belongs to this model."""
        with self._lock:
            if self._contributions is None:
                cached = self.run.folder.read_contributions()
                if cached is not None and cached.model == self.run.fingerprint:
                    self._contributions = cached
                else:
                    computed = mask_contributions(
                        self.run, self.scene_dir, masks=self.masks, backend=self.backend, progress=False
                    )
                    if not len(computed.labels):
                        raise InputError(
                            f"the run's scene holds no {self.masks} masks to relabel from; build them "
                            "with `hqmask build`."
                        )
                    with self.run.folder.lock():
                        self.run.folder.write_contributions(computed)
                    self._contributions = computed
            return self._contributions

    def frame(self, view: ViewCamera) -> np.ndarray:
        """(H, W, 3) uint8: the current model seen from ``view``, coloured by label when
        ``show_segments``, the selected object highlighted."""
        g, seg = self.current()
        selection = self.selection()
        if seg is not None and (self.show_segments or selection is not None):
            g = _painted(g, seg, self.show_segments, selection)
        filled = self.fill(wait=False)
        if filled is not None:
            g = Gaussians.concat(g, filled.gaussians.select(slice(len(g), None)))
        with self._lock:
            background = edit_background(s.op for s in self.steps)
        return self.run.render_rgb(view, gaussians=g, background=background, backend=self.backend)

    def save(self, name: str, *, split: str = "test", overwrite: bool = False) -> Path:
        """Write the current model as ``RUN/edits/NAME/`` (as ``gsseg edit`` does)."""
        with self._lock:
            steps = list(self.steps)
        if not steps:
            raise InputError("nothing to save: remove, extract or recolour an object first.")
        g, _ = self.current()
        filled = self.fill()
        seg = self.segmentation
        record = {
            "steps": [
                {
                    "op": s.op,
                    "object_id": s.object_id,
                    "color": s.color,
                    **({} if s.selection is None else {"selected_gaussians": int(s.selection.sum())}),
                }
                for s in steps
            ],
            "labels": seg.settings(),
            "gaussians": len(g),
            **({} if filled is None else {"removal_fill": filled.record()}),
        }
        return write_edit(
            self.run,
            g if filled is None else filled.gaussians,
            self.run.folder.edit(name),
            record,
            scene=self.scene,
            background=edit_background(s.op for s in steps),
            split=split,
            backend=self.backend,
            overwrite=overwrite,
            progress=False,
        )


def _painted(g: Gaussians, seg: Segmentation, by_label: bool, selected: np.ndarray | None) -> Gaussians:
    """``g`` with every Gaussian in its label's colour (``by_label``) and the (N,) bool
    ``selected`` ones drawn halfway towards :data:`HIGHLIGHT`; view-dependent colour dropped
    where painted."""
    sh_dc, sh_rest = g.sh_dc.clone(), g.sh_rest.clone()
    if by_label:
        sh_dc = rgb_to_sh_dc(torch.from_numpy(label_palette()[seg.labels] / 255.0).float())
        sh_rest.zero_()
    if selected is not None:
        mask = torch.from_numpy(selected)
        sh_dc[mask] = 0.5 * sh_dc[mask] + 0.5 * rgb_to_sh_dc(torch.tensor(HIGHLIGHT))
        sh_rest[mask] = 0
    return Gaussians(**{**g.tensors(), "sh_dc": sh_dc, "sh_rest": sh_rest})
