"""Joint training of 3D-GS and per-Gaussian object features."""

from gsseg.train.trainer import TrainingDiverged, TrainResult, train
from gsseg.train_config import TrainConfig

__all__ = ["TrainConfig", "TrainResult", "TrainingDiverged", "train"]
