"""A trained run, loaded from its folder, and how it renders a view."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal, Protocol

import numpy as np
import torch

from dataset_tools.cameras import PinholeCamera
from dataset_tools.scene import Scene, load_scene
from gsseg.environment import Environment, background_image
from gsseg.gaussians import Gaussians, make_classifier
from gsseg.ply import read_ply
from gsseg.render import Backend, RenderOutput, get_backend, render, to_uint8
from gsseg.run_folder import RunFolder
from gsseg.train.config import RunRecord, TrainConfig

Background = Literal["environment", "white", "black"]


class Posed(Protocol):
    """Anything with a pinhole camera and a (3, 4) world-to-camera pose, such as a scene View."""

    camera: PinholeCamera
    cam_from_world: np.ndarray


@dataclass
class Run:
    """The model of a finished run and the record of how it was trained."""

    folder: RunFolder
    record: RunRecord
    gaussians: Gaussians
    classifier: torch.nn.Linear
    environment: Environment | None = None  # None: the run renders on black
    _on_device: dict[str, Gaussians] = field(default_factory=dict, repr=False)

    @property
    def root(self) -> Path:
        return self.folder.root

    @property
    def config(self) -> TrainConfig:
        return self.record.config

    @property
    def images(self) -> str:
        """The image folder of the scene the run was trained on (``images`` or ``images_N``)."""
        return self.config.images

    def scene(self, scene_dir: Path | str | None = None, *, masks: str | None = None,
              images: str | None = None) -> Scene:
        """The scene the run was trained on (or ``scene_dir``), at the run's image size."""
        return load_scene(scene_dir or self.record.scene, images=images or self.images, masks=masks)

    def gaussians_on(self, device: str) -> Gaussians:
        """The run's Gaussians on ``device`` (moved once, then kept)."""
        if device not in self._on_device:
            self._on_device[device] = self.gaussians.to(device)
        return self._on_device[device]

    @torch.no_grad()
    def render(self, view: Posed, *, gaussians: Gaussians | None = None, background: Background = "environment",
               with_features: bool = False, sh_degree: int | None = None,
               backend: str | Backend = "auto") -> RenderOutput:
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
        return render(g, view.camera, pose, sh_degree=self.config.sh_degree if sh_degree is None else sh_degree,
                      background=bg, with_features=with_features, backend=backend)

    def render_rgb(self, view: Posed, **options) -> np.ndarray:
        """(H, W, 3) uint8 colour of :meth:`render`."""
        return to_uint8(self.render(view, **options).rgb)


def load_run(root: Path | str) -> Run:
    """Load the model of a finished training run."""
    folder = RunFolder(root)
    folder.require_finished()
    record = RunRecord.from_json(json.loads(folder.config.read_text()))
    state = torch.load(folder.classifier, map_location="cpu", weights_only=True)
    classifier = make_classifier(state["weight"].shape[0])
    classifier.load_state_dict(state)
    environment = None
    if folder.environment.is_file():
        environment = Environment.from_state(torch.load(folder.environment, map_location="cpu", weights_only=True))
    return Run(folder, record, read_ply(folder.gaussians), classifier, environment)

