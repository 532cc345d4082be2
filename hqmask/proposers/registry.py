"""Every mask proposer by the name ``hqmask build --proposer`` gives it."""

from __future__ import annotations

from pathlib import Path

from dataset_tools.infra.errors import OptionError
from hqmask.proposers.base import Proposer
from hqmask.proposers.existing import ExistingMasks
from hqmask.proposers.graph import GraphProposer


def make_proposer(
    name: str,
    model_dir: str | None = None,
    *,
    device: str = "auto",
    threads: int = 0,
    points_per_side: int = 32,
    embedding_cache: Path | None = None,
) -> Proposer:
    """The proposer called ``name``: ``graph``, ``existing`` or ``sam-hq``.

    The keyword options configure ``sam-hq``: ONNX Runtime device and threads, the point grid
    of the automatic generator, and a folder to cache image embeddings in.
    """
    if name == "graph":
        return GraphProposer()
    if name == "existing":
        return ExistingMasks()
    if name == "sam-hq":
        from hqmask.sam_hq import EXPORT_HINT, AutomaticMaskGenerator, GeneratorConfig, SamHQ
        from hqmask.sam_hq.proposer import SamHQProposer

        if not model_dir:
            raise OptionError(
                f"{{proposer}} needs {{model}}, a SAM-HQ ONNX model folder; {EXPORT_HINT}.", proposer="sam-hq"
            )
        model = SamHQ(model_dir, device=device, threads=threads, cache_dir=embedding_cache)
        return SamHQProposer(AutomaticMaskGenerator(model, GeneratorConfig(points_per_side=points_per_side)))
    raise OptionError("{proposer}: unknown proposer; use graph, sam-hq or existing.", proposer=name)
