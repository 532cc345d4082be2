"""The options of ``gsseg demo``, apart from the pipeline that runs them so that the command
line reads them without loading it."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

# The demo trains the cpu schedule shortened. 1500 steps and 30k Gaussians on the embedded
# 128x128 scene. On the user's capture the run renders about RUN_PIXELS pixels in
# all, since a step's time grows with its view's pixels: 2000 steps of 424x424 views, about
# 6 minutes with the object features on 2 cores; fewer steps for larger views, never under MIN_SCENE_ITERS, never over
# MAX_SCENE_ITERS. On nerd_ethiopian_head 2000 steps reached 21.6 dB where 1000 reached 19.8
# and the cpu schedule's 3000 steps with twice the Gaussians 22.7; 60k Gaussians instead of
# 30k gained 0.04 dB (docs/training.md).
EMBEDDED_ITERS = 1_500
RUN_PIXELS = 2_000 * 424 * 424
MIN_SCENE_ITERS = 1_000
MAX_SCENE_ITERS = 2_000
# The stages around the training (structure from motion, masks, the removal's fill) take
# about 3.5 s a photo on 2 cores (the statue's 29 photos 1.4 min, the head's 66 4.4, the
# bear's 96 5.7), so past FULL_RUN_VIEWS photos the run's pixels shrink in proportion to keep
# the whole demo near 10 minutes: the bear's 96 train 1200 steps, not 1400 (22.41 dB against
# 22.67; docs/training.md).
FULL_RUN_VIEWS = 80
# The cap: 30k Gaussians, or room for densification to double the SfM points where they are
# more than half of that (gaussctrl_bear's 34 790 points left no room under 30k: 22.05 dB in
# 1400 steps and 293 s of colour-only training, 22.80 with 70k in 330 s), up to
# MAX_SCENE_GAUSSIANS.
MIN_SCENE_GAUSSIANS = 30_000
GAUSSIANS_PER_POINT = 2
MAX_SCENE_GAUSSIANS = 100_000


@dataclass(frozen=True)
class DemoOptions:
    """What ``gsseg demo`` runs on and how long it trains.

    Attributes:
        scene: the user's scene folder, folder of photos or video; None: the embedded
            synthetic scene.
        images: the image folder of ``scene``; None: its largest copy at most ``max_side``
            pixels.
        iters: training iterations; None: :data:`EMBEDDED_ITERS` on the embedded scene, the
            capture's (:func:`capture_iters`) on the user's
            (:func:`pipeline.demo.demo_training`).
        max_gaussians: densification stops at this many Gaussians; None:
            :data:`MIN_SCENE_GAUSSIANS` on the embedded scene, the capture's
            (:func:`capture_gaussians`) on the user's.
        max_side: the longest image side the default ``images`` may have.
        backend: the renderer (``auto``: gsplat where it can run, else cpu).
    """

    scene: Path | None = None
    images: str | None = None
    iters: int | None = None
    max_gaussians: int | None = None
    max_side: int = 640
    backend: str = "auto"


def capture_pixels(views: int) -> float:
    """The pixels the demo's run renders in all on a capture of ``views`` photos:
    :data:`RUN_PIXELS`, times :data:`FULL_RUN_VIEWS` / ``views`` past that many photos."""
    return RUN_PIXELS * min(1.0, FULL_RUN_VIEWS / max(views, 1))


def capture_iters(view_pixels: int, views: int) -> int:
    """The demo's training steps on a capture of ``views`` photos whose views have
    ``view_pixels`` pixels each: :func:`capture_pixels` in all, in hundreds of steps, between
    :data:`MIN_SCENE_ITERS` and :data:`MAX_SCENE_ITERS`."""
    steps = round(capture_pixels(views) / max(view_pixels, 1), -2)
    return int(min(max(steps, MIN_SCENE_ITERS), MAX_SCENE_ITERS))


def capture_gaussians(points: int) -> int:
    """The demo's Gaussian cap on a capture whose SfM model has ``points`` points:
    :data:`GAUSSIANS_PER_POINT` per point in thousands (rounded up), between
    :data:`MIN_SCENE_GAUSSIANS` and :data:`MAX_SCENE_GAUSSIANS`."""
    cap = -(-GAUSSIANS_PER_POINT * points // 1_000) * 1_000
    return int(min(max(cap, MIN_SCENE_GAUSSIANS), MAX_SCENE_GAUSSIANS))
