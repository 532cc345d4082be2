"""The options of a removal's fill (:mod:`gsseg.fill`), apart from the code that runs it so
that the command lines read them without loading it."""

from __future__ import annotations

from dataclasses import dataclass

from gsseg.train.config import TrainConfig


@dataclass(frozen=True)
class FillOptions:
    """How a removal is filled.

    Attributes:
        steps: optimisation steps of the fill, one view each.
        views: at most this many of the views with unseen pixels seed new Gaussians.
        fit_views: the unseen pixels are found, inpainted and fitted to in at most this many
            of the views the object shows in, spread over them (each is tested against every
            training view, each of which is still rendered once).
        stride: pixels between the new Gaussians seeded in each fitted view.
        rim: pixels the object's silhouettes are widened by (its blurred edge).
        margin: pixels of the removal's render kept as they are around each hole in the fit.
        depth_tolerance: relative depth difference under which another view sees a point.
        depth_radius: width in pixels of the ring around a hole whose surface is carried across it.
        initial_opacity: opacity of a new Gaussian.
        lambda_dssim: weight of the SSIM term in the fit's loss, training's.
        seed: seeds the choice of view at each step.
    """

    steps: int = 600
    views: int = 12
    fit_views: int = 32
    stride: int = 3
    rim: int = 2
    margin: int = 12
    depth_tolerance: float = 0.02
    depth_radius: int = 5
    initial_opacity: float = 0.9
    lambda_dssim: float = TrainConfig.lambda_dssim
    seed: int = 0
