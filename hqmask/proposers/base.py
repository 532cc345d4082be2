"""What a mask proposer returns, and the interface every proposer implements."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from dataset_tools.scene import View
from hqmask.support_plane import Heights


@dataclass
class Proposals:
    """Candidate masks of one image: masks (N, H, W) bool, scores (N,) float."""

    masks: np.ndarray
    scores: np.ndarray

    def paint(self) -> np.ndarray:
        """Segment map (H, W) int32: proposal k+1 where it wins, 0 elsewhere; a pixel covered by
        several proposals takes the highest-scoring one."""
        H, W = self.masks.shape[1:]
        seg = np.zeros((H, W), np.int32)
        for k in np.argsort(self.scores, kind="stable"):
            seg[self.masks[k]] = k + 1
        return seg


class Proposer(Protocol):
    #: Folder name of the per-view proposal cache (it names everything the proposals depend
    #: on), or None for proposers not worth caching.
    cache_name: str | None
    #: Whether ``propose`` runs on one core, mostly outside the GIL, and may be called from
    #: several threads at once: a local build then proposes as many views at once as it has CPUs.
    threadable: bool

    def propose(
        self, image: np.ndarray, view: View, depth: np.ndarray | None = None, height: Heights | None = None
    ) -> Proposals:
        """Candidate masks for ``image`` (H, W, 3) uint8, the loaded image of ``view``;
        ``depth`` (H, W), the view's camera depth (0: nothing opaque), and ``height``, each
        pixel's height above the scene's support plane, where the build has them (a proposer
        may ignore them)."""
        ...
