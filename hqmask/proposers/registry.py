"""Every mask proposer by the name ``hqmask build --proposer`` gives it: a new proposer is an
entry here and its module."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from dataset_tools.infra.errors import OptionError
from hqmask.build_options import BuildConfig
from hqmask.proposers.base import Proposer
from hqmask.proposers.existing import ExistingMasks
from hqmask.proposers.graph import GraphProposer


def _sam_hq(cfg: BuildConfig, embedding_cache: Path | None) -> Proposer:
    """SAM-HQ's automatic generator on ONNX Runtime (``cfg.device``, ``cfg.threads``), on a
    grid of ``cfg.points_per_side`` points a side (by default the generator's)."""
    from hqmask.sam_hq import EXPORT_HINT, AutomaticMaskGenerator, GeneratorConfig, SamHQ
    from hqmask.sam_hq.proposer import SamHQProposer

    if not cfg.model:
        raise OptionError(
            f"{{proposer}} needs {{model}}, a SAM-HQ ONNX model folder; {EXPORT_HINT}.", proposer="sam-hq"
        )
    model = SamHQ(cfg.model, device=cfg.device, threads=cfg.threads, cache_dir=embedding_cache)
    grid = GeneratorConfig() if cfg.points_per_side is None else GeneratorConfig(points_per_side=cfg.points_per_side)
    return SamHQProposer(AutomaticMaskGenerator(model, grid))


PROPOSERS: dict[str, Callable[[BuildConfig, Path | None], Proposer]] = {
    "graph": lambda cfg, embedding_cache: GraphProposer(),
    "sam-hq": _sam_hq,
    "existing": lambda cfg, embedding_cache: ExistingMasks(),
}


def make_proposer(cfg: BuildConfig, embedding_cache: Path | None = None) -> Proposer:
    """The proposer ``cfg.proposer`` configured by ``cfg``; ``embedding_cache``: a folder to
    keep SAM-HQ's image embeddings in."""
    if cfg.proposer not in PROPOSERS:
        raise OptionError(f"{{proposer}}: unknown proposer; use {', '.join(PROPOSERS)}.", proposer=cfg.proposer)
    return PROPOSERS[cfg.proposer](cfg, embedding_cache)
