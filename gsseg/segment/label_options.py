"""The options of label reassignment and their choices, apart from the code that runs them so
that the command lines read them without loading it."""

from __future__ import annotations

import math
from dataclasses import dataclass

from dataset_tools.infra.errors import OptionError

METHODS = ("prior", "flashsplat", "classifier")  # see gsseg.segment.reassign.reassign
MODES = ("multi", "binary")


@dataclass(frozen=True)
class LabelOptions:
    """How labels are chosen: the reassignment (``method``, ``mode``, ``gamma_p``, ``slack``,
    see :func:`reassign`) and the 3D regularisation after it (``smooth``: neighbours that
    relabel weak Gaussians, 0 off; ``fill``: objects take the Gaussians they enclose). Checked
    when made: the functions that take them check nothing again."""

    method: str = "prior"
    mode: str = "multi"
    gamma_p: float = 0.2
    slack: float = 0.0
    smooth: int = 0
    fill: bool = False

    def __post_init__(self) -> None:
        if self.method not in METHODS:
            raise OptionError(f"{{method}}: choose one of {', '.join(METHODS)}.", method=self.method)
        if self.mode not in MODES:
            raise OptionError(f"{{mode}}: choose one of {', '.join(MODES)}.", mode=self.mode)
        if not (math.isfinite(self.gamma_p) and math.isfinite(self.slack)):
            raise OptionError("{gamma_p} / {slack}: give finite numbers.", gamma_p=self.gamma_p, slack=self.slack)
        if self.smooth < 0:
            raise OptionError("{smooth}: give 0 (off) or a number of neighbours.", smooth=self.smooth)
        if (self.smooth or self.fill) and self.mode != "multi":
            raise OptionError("{smooth} and {fill} relabel Gaussians one label each; use {mode}.", mode="multi")
