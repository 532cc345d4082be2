"""The options of ``gsseg demo``, apart from the pipeline that runs them so that the command
line reads them without loading it."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

# The demo trains the cpu schedule shortened, with at most 30k Gaussians (about two per pixel
# of a 128x128 view): 1500 steps on the embedded 128x128 scene; 1000 on the user's, whose
# views of up to 640 px cost several times more a step (497x372: 5 steps a second on 2
# cores), so that photos to edits take about 5 minutes.
EMBEDDED_ITERS = 1_500
SCENE_ITERS = 1_000


@dataclass(frozen=True)
class DemoOptions:
    """What ``gsseg demo`` runs on and how long it trains.

    Attributes:
        scene: the user's scene folder, folder of photos or video; None: the embedded
            synthetic scene.
        images: the image folder of ``scene``; None: its largest copy at most ``max_side``
            pixels.
        iters: training iterations; None: :data:`EMBEDDED_ITERS` on the embedded scene,
            :data:`SCENE_ITERS` on the user's.
        max_gaussians: densification stops at this many Gaussians.
        max_side: the longest image side the default ``images`` may have.
        backend: the renderer (``auto``: gsplat where it can run, else cpu).
    """

    scene: Path | None = None
    images: str | None = None
    iters: int | None = None
    max_gaussians: int = 30_000
    max_side: int = 640
    backend: str = "auto"

    @property
    def train_iters(self) -> int:
        """The iterations trained: ``iters``, or the default of the scene's kind."""
        if self.iters is not None:
            return self.iters
        return EMBEDDED_ITERS if self.scene is None else SCENE_ITERS
