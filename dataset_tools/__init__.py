"""Scene folders, synthetic scenes with exact ground truth, and mask corruption.

The scene folder (images, ``images_N``, ``sparse/0``, ``object_mask``, ``scene.json``; a
synthetic scene's exact masks in ``gt_mask``) is the interchange format between every stage
of the pipeline.
"""

from dataset_tools.infra.errors import InputError
from dataset_tools.scene import PinholeCamera, Scene, SparsePoints, View, load_scene, save_scene

__all__ = [
    "InputError",
    "PinholeCamera",
    "Scene",
    "SparsePoints",
    "View",
    "load_scene",
    "save_scene",
]
