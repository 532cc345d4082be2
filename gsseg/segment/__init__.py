"""Segmentation: prior-guided label reassignment from the contribution matrix, and prompts."""

from gsseg.segment.prompts import object_at_point, pick_object, point_from_click
from gsseg.segment.reassign import METHODS, MODES, Segmentation, classifier_prior, reassign

__all__ = [
    "object_at_point",
    "pick_object",
    "point_from_click",
    "METHODS",
    "MODES",
    "Segmentation",
    "classifier_prior",
    "reassign",
]
