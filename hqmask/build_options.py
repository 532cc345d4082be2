"""The options of ``hqmask build``, apart from the code that runs them so that the command
line reads them without loading it."""

from __future__ import annotations

from dataclasses import dataclass

from dataset_tools.infra.errors import OptionError
from dataset_tools.infra.names import plain_name
from dataset_tools.scene import IMAGES, MASKS

ASSOCIATIONS = ("auto", "flow", "tracks")  # auto: tracks where the scene has SfM observations


def check_min_area(min_area: int | None) -> None:
    """Refuse a component size under 1 pixel (None: the paper's, scaled to each view)."""
    if min_area is not None and min_area < 1:
        raise OptionError("{min_area}: give a number of pixels of 1 or more (or leave it out).", min_area=min_area)


@dataclass(frozen=True)
class BuildConfig:
    """Options of ``hqmask build`` (same names as the CLI)."""

    proposer: str = "graph"
    from_masks: str | None = None
    model: str | None = None
    associate: str = "auto"  # tracks where the scene has SfM observations, flow otherwise
    consensus: int = 4  # neighbouring views that vote on each view's labels; 0: off
    min_area: int | None = None  # None: the paper's 500 px at 1008x756, scaled to each view
    out_masks: str = MASKS
    images: str = IMAGES
    dataset: str | None = None
    force: bool = False
    device: str = "auto"
    threads: int = 0
    points_per_side: int | None = None  # sam-hq's point grid; None: the generator's (SAM's 32)
    cache_embeddings: bool = False
    depth: str | None = None  # folder of <stem>.npy depth maps (``gsseg render --what depth``); graph only

    def __post_init__(self) -> None:
        if self.associate not in ASSOCIATIONS:
            raise OptionError(f"{{associate}}: use {', '.join(ASSOCIATIONS)}.", associate=self.associate)
        plain_name(self.out_masks, "out_masks")
        check_min_area(self.min_area)
        if self.points_per_side is not None and self.points_per_side < 1:
            raise OptionError(
                "{points_per_side}: give 1 or more points per side of the grid.", points_per_side=self.points_per_side
            )
        if self.threads < 0:
            raise OptionError("{threads}: give 0 (ONNX Runtime's choice) or a number of threads.", threads=self.threads)
        if self.consensus < 0:
            raise OptionError("{consensus}: use 0 (off) or a number of neighbouring views.", consensus=self.consensus)
        if self.proposer == "existing" and not self.from_masks:
            raise OptionError("{proposer} needs {from_masks}, the mask folder to re-associate.", proposer="existing")
        if self.depth is not None and self.proposer != "graph":
            raise OptionError(
                "{depth}: only the graph proposer cuts its masks at depth jumps; leave {depth} out with {proposer}.",
                proposer=self.proposer,
            )
