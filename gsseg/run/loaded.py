"""A trained run, loaded from its folder, and how it renders a view."""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Literal, Protocol

import numpy as np
import torch

from dataset_tools.cameras import PinholeCamera
from dataset_tools.infra.errors import InputError, OptionError
from dataset_tools.infra.overlap import Protected, run_inputs, scene_entries
from dataset_tools.scene import Scene, load_scene
from gsseg.model.environment import Environment, background_image
from gsseg.model.gaussians import Gaussians
from gsseg.render import Backend, RenderOutput, get_backend, render, to_uint8
from gsseg.run.folder import RunFolder
from gsseg.run.record import RunRecord, scene_difference
from gsseg.segment.reassign import Segmentation
from gsseg.train.config import TrainConfig

Background = Literal["environment", "white", "black"]


class Posed(Protocol):
    """Anything with a pinhole camera and a (3, 4) world-to-camera pose, such as a scene View."""

    camera: PinholeCamera
    cam_from_world: np.ndarray


@dataclass
class Run:
    """The model of a finished run and the record of how it was trained.

    ``fingerprint`` names the model (a hash of gaussians.ply): labels made for another model
    of the same folder (before a ``--resume`` that changed it) are refused.
    """

    folder: RunFolder
    record: RunRecord
    gaussians: Gaussians
    classifier: torch.nn.Linear
    environment: Environment | None = None  # None: the run renders on black
    other_scene: bool = False  # accept a scene other than the recorded one (--allow-other-scene)
    _on_device: dict[str, Gaussians] = field(default_factory=dict, repr=False)

    @property
    def root(self) -> Path:
        return self.folder.root

    @cached_property
    def fingerprint(self) -> str:
        return self.folder.model_fingerprint()

    def labels(self) -> Segmentation:
        """``labels.npz``, refused when it labels another model than the run's."""
        segmentation = self.folder.read_labels()
        if len(segmentation.labels) != len(self.gaussians) or segmentation.model not in ("", self.fingerprint):
            raise InputError(
                f"{self.folder.labels}: labels another model than {self.folder.gaussians} (trained "
                "again since); run `gsseg segment` on the run again."
            )
        return segmentation

    @property
    def config(self) -> TrainConfig:
        return self.record.config

    @property
    def masks(self) -> str | None:
        """The mask folder the run was trained on (None: trained on colour alone)."""
        return self.config.masks

    def voting_masks(self, masks: str | None = None) -> str:
        """The mask folder that votes in ``gsseg segment``: ``masks``, else the one the run was
        trained on; a run trained on colour alone has none to fall back to (the scene's
        ``object_mask`` may be another tool's masks)."""
        chosen = masks or self.config.masks
        if chosen is None:
            raise OptionError(
                "trained on colour alone, so no mask folder votes by default; name one with {masks}.", file=self.root
            )
        return chosen

    @property
    def images(self) -> str:
        """The image folder of the scene the run was trained on (``images`` or ``images_N``)."""
        return self.config.images

    def scene(
        self, scene_dir: Path | str | None = None, *, masks: str | None = None, images: str | None = None
    ) -> Scene:
        """The scene the run was trained on, at the run's image size; ``scene_dir`` names it
        where it moved, and is refused when it is not the scene the run recorded (its views,
        cameras, poses or images differ) unless the run was loaded with ``other_scene``."""
        if scene_dir is None and not Path(self.record.scene).is_dir():
            raise OptionError(
                "the scene this run was trained on is no longer there; pass where it moved as {scene_dir}.",
                file=self.record.scene,
            )
        scene = load_scene(scene_dir or self.record.scene, images=images or self.images, masks=masks)
        if self.record.scene_fingerprint is None and not self.other_scene:
            warnings.warn(
                f"{self.folder.config}: records no fingerprint of its scene (trained before they were recorded); "
                f"{scene.root} is checked by its view names alone.",
                stacklevel=2,
            )
        difference = None if self.other_scene else scene_difference(self.record, scene)
        if difference is not None:
            raise OptionError(
                f"not the scene {self.root} was trained on ({difference}); pass that scene, or {{other_scene}} to "
                "use this one.",
                file=scene.root,
                other_scene=True,
            )
        return scene

    def inputs(self, scene_dir: Path | str | None = None) -> list[Protected]:
        """What a command that reads the run and its scene (``scene_dir``, default the
        recorded one) must never write over: the run folder and everything in the scene."""
        return [*run_inputs(self.root), *scene_entries(scene_dir or self.record.scene)]

    def gaussians_on(self, device: str) -> Gaussians:
        """The run's Gaussians on ``device`` (moved once, then kept)."""
        if device not in self._on_device:
            self._on_device[device] = self.gaussians.to(device)
        return self._on_device[device]

    @torch.no_grad()
    def render(
        self,
        view: Posed,
        *,
        gaussians: Gaussians | None = None,
        background: Background = "environment",
        with_features: bool = False,
        sh_degree: int | None = None,
        backend: str | Backend = "auto",
    ) -> RenderOutput:
        """Render ``view`` with the run's Gaussians (or edited ones, ``gaussians``) over its
        learned environment, white or black, at the run's SH degree unless told otherwise."""
        backend = get_backend(backend)
        g = self.gaussians_on(backend.device) if gaussians is None else gaussians.to(backend.device)
        pose = torch.as_tensor(view.cam_from_world, dtype=torch.float32, device=backend.device)
        if background == "environment":
            bg = background_image(self.environment, view.camera, pose)
        elif background == "white":
            bg = torch.ones(3, device=backend.device)
        else:
            bg = None
        return render(
            g,
            view.camera,
            pose,
            sh_degree=self.config.sh_degree if sh_degree is None else sh_degree,
            background=bg,
            with_features=with_features,
            backend=backend,
        )

    def render_rgb(self, view: Posed, **options) -> np.ndarray:
        """(H, W, 3) uint8 colour of :meth:`render`."""
        return to_uint8(self.render(view, **options).rgb)


def load_run(root: Path | str, *, other_scene: bool = False) -> Run:
    """Load the model of a finished training run; damaged files are refused in one sentence.
    ``other_scene``: :meth:`Run.scene` accepts a scene other than the one the run recorded."""
    folder = RunFolder(root)
    folder.require_finished()
    return Run(
        folder,
        folder.read_config(),
        folder.read_gaussians(),
        folder.read_classifier(),
        folder.read_environment(),
        other_scene,
    )
