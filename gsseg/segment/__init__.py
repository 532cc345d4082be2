"""Stage C: contribution matrix, prior-guided label reassignment, prompts."""

from gsseg.segment.contributions import Contributions, MaskedView, contribution_matrix
from gsseg.segment.prompts import object_at_point, pick_object, point_from_click
from gsseg.segment.reassign import METHODS, MODES, Segmentation, classifier_prior, reassign

__all__ = ["Contributions", "MaskedView", "contribution_matrix", "object_at_point", "pick_object", "point_from_click",
           "METHODS", "MODES", "Segmentation", "classifier_prior", "reassign"]
