"""Structure from motion on the CPU with pycolmap: a scene folder from a folder of photos or a
phone video (:func:`run_sfm`; ``python -m dataset_tools sfm``)."""

from dataset_tools.sfm.pipeline import SfmConfig, SfmResult, run_sfm

__all__ = ["SfmConfig", "SfmResult", "run_sfm"]
