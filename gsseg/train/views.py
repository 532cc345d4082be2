"""The training views: kept compact (uint8 colour and IDs, 4 bytes a pixel) in memory, or read
from disk a few steps ahead of the training loop, and turned into float tensors on the
device one step at a time."""

from __future__ import annotations

import os
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
import torch
from tqdm import tqdm

from dataset_tools.cameras import PinholeCamera
from dataset_tools.infra.errors import OptionError
from dataset_tools.scene import View

CACHE_MODES = ("auto", "memory", "disk")
MEMORY_SHARE = 0.25  # `auto` keeps the views in memory while they need at most this share of the RAM


@dataclass
class TrainView:
    """One view ready for a training step.

    Attributes:
        image: (H, W, 3) float32 in [0, 1], on the device.
        mask: (H, W) int64 object IDs on the device, or None for a view trained on colour only.
        cam_from_world: (3, 4) float32.
    """

    name: str
    camera: PinholeCamera
    cam_from_world: torch.Tensor
    image: torch.Tensor
    mask: torch.Tensor | None


@dataclass
class _Pixels:
    """A view's pixels as read: (H, W, 3) uint8 colour and (H, W) uint8 IDs or None."""

    image: np.ndarray
    mask: np.ndarray | None

    @classmethod
    def read(cls, view: View) -> _Pixels:
        return cls(view.load_image(), view.load_mask())

    def moved_into(self, store: np.ndarray, offset: int) -> _Pixels:
        """The same pixels as views of ``store`` from ``offset`` (4 bytes a pixel: colour, then IDs)."""
        h, w = self.image.shape[:2]
        image = store[offset : offset + 3 * h * w].reshape(h, w, 3)
        image[:] = self.image
        mask = None
        if self.mask is not None:
            mask = store[offset + 3 * h * w : offset + 4 * h * w].reshape(h, w)
            mask[:] = self.mask
        return _Pixels(image, mask)


def view_bytes(views: list[View]) -> int:
    """The bytes the views' uint8 colour and IDs take: 4 a pixel."""
    return sum(4 * v.camera.width * v.camera.height for v in views)


def resolve_cache_mode(mode: str, views: list[View]) -> str:
    """``memory`` or ``disk``: ``auto`` keeps the views in memory while they fit in
    :data:`MEMORY_SHARE` of the machine's RAM."""
    if mode not in CACHE_MODES:
        raise OptionError(f"{{cache_views}}: choose one of {', '.join(CACHE_MODES)}.", cache_views=mode)
    if mode != "auto":
        return mode
    ram = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    return "memory" if view_bytes(views) <= MEMORY_SHARE * ram else "disk"


class TrainViews:
    """The training views, fetched by training step.

    Args:
        views: the scene's training views.
        schedule: the view index trained at a step (a function of the step alone).
        mode: ``memory`` (read once, kept as uint8), ``disk`` (read when needed; the views of
            the next ``prefetch`` steps are read ahead on a background thread, so a step
            never waits for the disk while reading a view takes less than a step) or
            ``auto`` (:func:`resolve_cache_mode`).
        device: where the float tensors of a step are made.

    Every image and mask is read once up front in either mode, so a damaged file is
    refused before the first step.
    """

    def __init__(
        self,
        views: list[View],
        schedule: Callable[[int], int],
        *,
        mode: str = "auto",
        device: str = "cpu",
        prefetch: int = 3,
        progress: bool = True,
    ) -> None:
        self.views = views
        self.schedule = schedule
        self.mode = resolve_cache_mode(mode, views)
        self.device = device
        self.prefetch = prefetch
        self.poses = [torch.as_tensor(v.cam_from_world, dtype=torch.float32, device=device) for v in views]
        self._kept: list[_Pixels] = []
        self._ahead: dict[int, Future] = {}
        self._pool = ThreadPoolExecutor(1, thread_name_prefix="views") if self.mode == "disk" else None
        # memory: every view's pixels in one block allocated once, so that the decoders'
        # temporary buffers are not left as holes between the views that stay
        store = np.empty(view_bytes(views) if self.mode == "memory" else 0, np.uint8)
        offset = 0
        for v in tqdm(views, desc="loading views", unit="view", disable=not progress, leave=False):
            pixels = _Pixels.read(v)
            if self.mode == "memory":
                self._kept.append(pixels.moved_into(store, offset))
                offset += 4 * v.camera.width * v.camera.height

    def __len__(self) -> int:
        return len(self.views)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(v.name for v in self.views)

    @property
    def resident_bytes(self) -> int:
        """The bytes of pixels held now: every view in memory mode, those read ahead on disk."""
        held = self._kept + [f.result() for f in self._ahead.values() if f.done() and not f.exception()]
        return sum(p.image.nbytes + (0 if p.mask is None else p.mask.nbytes) for p in held)

    def at_step(self, step: int) -> TrainView:
        """The view trained at ``step``, as float tensors on the device."""
        index = self.schedule(step)
        if self._pool is None:
            pixels = self._kept[index]
        else:
            pending = self._ahead.pop(step, None)
            pixels = pending.result() if pending is not None else _Pixels.read(self.views[index])
            for ahead in range(step + 1, step + 1 + self.prefetch):
                if ahead not in self._ahead:
                    self._ahead[ahead] = self._pool.submit(_Pixels.read, self.views[self.schedule(ahead)])
        view = self.views[index]
        image = torch.from_numpy(pixels.image).to(self.device).float() / 255.0
        mask = None if pixels.mask is None else torch.from_numpy(pixels.mask).to(self.device).long()
        return TrainView(view.name, view.camera, self.poses[index], image, mask)

    def close(self) -> None:
        """Stop reading ahead."""
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._ahead.clear()


def camera_extent(views: list[View]) -> float:
    """3D-GS's scene scale: 1.1 x the largest distance of a camera centre from their mean."""
    centers = np.stack([v.center for v in views])
    return 1.1 * float(np.linalg.norm(centers - centers.mean(0), axis=1).max()) or 1.0
