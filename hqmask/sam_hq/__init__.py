"""SAM-HQ through ONNX Runtime: export, image encoding, prompts, automatic mask generation."""

from hqmask.sam_hq.generator import AutomaticMaskGenerator, GeneratedMasks, GeneratorConfig
from hqmask.sam_hq.model import EXPORT_HINT, ImageEmbedding, ModelInfo, Prediction, SamHQ

__all__ = [
    "EXPORT_HINT",
    "AutomaticMaskGenerator",
    "GeneratedMasks",
    "GeneratorConfig",
    "ImageEmbedding",
    "ModelInfo",
    "Prediction",
    "SamHQ",
]
