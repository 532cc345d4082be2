"""The ``existing`` proposer: masks already on disk (a corrupted or another tool's folder),
one proposal per ID, to be associated and cleaned again."""

from __future__ import annotations

import numpy as np

from dataset_tools.scene import View
from hqmask.proposers.base import Proposals
from hqmask.support_plane import Heights


def _from_label_map(ids: np.ndarray) -> Proposals:
    labels = np.unique(ids)
    labels = labels[labels > 0]
    return Proposals(ids[None] == labels[:, None, None], np.ones(len(labels)))


class ExistingMasks:
    """Proposals read from a mask folder of the scene: one proposal per ID of the view's map."""

    cache_name = None
    threadable = False  # reading a map is quick

    def propose(
        self, image: np.ndarray, view: View, depth: np.ndarray | None = None, height: Heights | None = None
    ) -> Proposals:
        ids = view.load_mask()
        if ids is None:
            return Proposals(np.zeros((0, *image.shape[:2]), bool), np.zeros(0))
        return _from_label_map(ids)
