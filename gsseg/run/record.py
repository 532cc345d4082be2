"""What a run's ``config.json`` holds: the training options and what the run was trained on."""

from __future__ import annotations

from dataclasses import dataclass

from dataset_tools.fingerprint import fingerprint_difference
from dataset_tools.scene import Scene
from gsseg.train.config import TrainConfig


@dataclass(frozen=True)
class RunRecord:
    """What a run's config.json holds: its options and what it was trained on.

    Attributes:
        config: the options.
        scene: the absolute path of the scene folder it was trained on.
        backend_used: the backend ``config.backend`` resolved to.
        extent: 3D-GS's scene scale (1.1 x the largest camera distance from their mean).
        near_plane: the scene's near plane, or None for runs from before it was recorded.
        train_views: the names of the views it was trained on.
        scene_fingerprint: :func:`dataset_tools.fingerprint.scene_fingerprint` of the scene, or
            None for runs from before it was recorded.
    """

    config: TrainConfig
    scene: str
    backend_used: str
    extent: float
    near_plane: float | None
    train_views: tuple[str, ...]
    scene_fingerprint: dict | None = None

    def to_json(self) -> dict:
        return {
            **self.config.to_json(),
            "scene": self.scene,
            "backend_used": self.backend_used,
            "extent": self.extent,
            "near_plane": self.near_plane,
            "train_views": list(self.train_views),
            "scene_fingerprint": self.scene_fingerprint,
        }

    @classmethod
    def from_json(cls, data: dict) -> RunRecord:
        return cls(
            config=TrainConfig.from_json(data),
            scene=data["scene"],
            backend_used=data["backend_used"],
            extent=float(data["extent"]),
            near_plane=data.get("near_plane"),
            train_views=tuple(data.get("train_views", ())),
            scene_fingerprint=data.get("scene_fingerprint"),
        )


def scene_difference(record: RunRecord, scene: Scene) -> str | None:
    """What makes ``scene`` another scene than the one ``record`` was trained on, in words, or
    None. Runs from before the fingerprint compare the names of the training views alone."""
    if record.scene_fingerprint is not None:
        return fingerprint_difference(record.scene_fingerprint, scene)
    missing = sorted(set(record.train_views) - {v.name for v in scene.views})
    return f"{len(missing)} of its views are missing, e.g. {missing[0]}" if missing else None
