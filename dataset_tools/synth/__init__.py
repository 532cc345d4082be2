"""Ray-cast synthetic scenes of analytic primitives with exact object masks.

Independent of any splatting code: images, object masks and SfM points are computed by
intersecting camera rays with spheres, boxes, cylinders, a ground plane and a back wall.
"""

from dataset_tools.synth.generator import SynthConfig, SynthResult, generate_scene

__all__ = ["SynthConfig", "SynthResult", "generate_scene"]
