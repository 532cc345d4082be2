"""SAM-HQ as a mask proposer (``hqmask build --proposer sam-hq``)."""

from __future__ import annotations

import numpy as np

from dataset_tools.scene import View
from hqmask.proposers.base import Proposals
from hqmask.support_plane import Heights


class SamHQProposer:
    """SAM-HQ's automatic mask generator (ONNX Runtime); proposals scored by predicted IoU."""

    def __init__(self, generator):
        """``generator``: a :class:`hqmask.sam_hq.AutomaticMaskGenerator`."""
        self.generator = generator
        points = generator.config.points_per_side
        self.cache_name = f"sam-hq-{generator.model.fingerprint}-p{points}"
        self.threadable = False  # ONNX Runtime already runs on every core

    def propose(
        self, image: np.ndarray, view: View, depth: np.ndarray | None = None, height: Heights | None = None
    ) -> Proposals:
        return self.generator.generate(image).proposals()
