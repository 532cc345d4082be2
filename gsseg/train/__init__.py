"""Joint training of 3D-GS and per-Gaussian object features."""

from gsseg.train.config import TrainConfig
from gsseg.train.trainer import TrainingDiverged, TrainResult, train

__all__ = ["TrainConfig", "TrainResult", "TrainingDiverged", "train"]
