"""The Gaussian model: geometry, SH colour and the 16-d object feature of every Gaussian."""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np
import torch
from scipy.spatial import cKDTree

from gsseg.model.sh import C0, MAX_DEGREE, num_coeffs, rgb_to_sh_dc

OBJ_FEAT_DIM = 16


def make_classifier(num_classes: int) -> torch.nn.Linear:
    """The linear layer from object features to class logits."""
    return torch.nn.Linear(OBJ_FEAT_DIM, num_classes)


_TRAILING_SHAPES = {
    "means": (3,),
    "log_scales": (3,),
    "quats": (4,),
    "opacity_logits": (),
    "sh_dc": (3,),
    "sh_rest": (num_coeffs(MAX_DEGREE) - 1, 3),
    "obj_feat": (None,),  # any width; 16 in trained runs (OBJ_FEAT_DIM)
}


@dataclass
class Gaussians:
    """N anisotropic 3D Gaussians in their optimisation parameterisation (as 3D-GS stores them).

    Attributes:
        means: (N, 3) centres in world coordinates.
        log_scales: (N, 3) log standard deviations along the local axes.
        quats: (N, 4) rotations as (w, x, y, z) quaternions, not necessarily normalised.
        opacity_logits: (N,) logit of the opacity.
        sh_dc: (N, 3) degree-0 SH coefficients of the colour.
        sh_rest: (N, 15, 3) SH coefficients of bands 1..3 (zeros above the degree in use).
        obj_feat: (N, 16) view-invariant object features.
    """

    means: torch.Tensor
    log_scales: torch.Tensor
    quats: torch.Tensor
    opacity_logits: torch.Tensor
    sh_dc: torch.Tensor
    sh_rest: torch.Tensor
    obj_feat: torch.Tensor

    def __post_init__(self) -> None:
        """Every field must have N rows and its trailing shape, and the means' floating dtype
        and device; a mismatch is a ValueError naming the field."""
        first = self.means
        n = first.shape[0] if isinstance(first, torch.Tensor) and first.ndim else -1
        for name, tail in _TRAILING_SHAPES.items():
            t = getattr(self, name)
            shape = tuple(t.shape) if isinstance(t, torch.Tensor) else None
            if (
                shape is None
                or len(shape) != len(tail) + 1
                or shape[0] != n
                or any(d is not None and d != s for d, s in zip(tail, shape[1:]))
            ):
                expected = ("N", *("F" if d is None else d for d in tail))
                raise ValueError(f"Gaussians.{name}: shape {shape or type(t).__name__}, expected {expected}, N = {n}")
            if not t.is_floating_point() or t.dtype != first.dtype or t.device != first.device:
                raise ValueError(
                    f"Gaussians.{name}: {t.dtype} on {t.device}, expected the means' floating "
                    f"{first.dtype} on {first.device}"
                )

    def __len__(self) -> int:
        return self.means.shape[0]

    @classmethod
    def field_names(cls) -> tuple[str, ...]:
        return tuple(f.name for f in fields(cls))

    def tensors(self) -> dict[str, torch.Tensor]:
        return {name: getattr(self, name) for name in self.field_names()}

    @property
    def scales(self) -> torch.Tensor:
        """(N, 3) standard deviations."""
        return torch.exp(self.log_scales)

    @property
    def opacities(self) -> torch.Tensor:
        """(N,) opacities in (0, 1)."""
        return torch.sigmoid(self.opacity_logits)

    @property
    def base_colours(self) -> torch.Tensor:
        """(N, 3) the view-independent colour of the DC coefficients, in [0, 1]."""
        return (self.sh_dc * C0 + 0.5).clamp(0, 1)

    @property
    def sh(self) -> torch.Tensor:
        """(N, 16, 3) all SH coefficients, DC first."""
        return torch.cat([self.sh_dc[:, None], self.sh_rest], dim=1)

    def detach(self) -> Gaussians:
        return Gaussians(**{k: v.detach() for k, v in self.tensors().items()})

    def to(self, device: torch.device | str) -> Gaussians:
        return Gaussians(**{k: v.to(device) for k, v in self.tensors().items()})

    @classmethod
    def concat(cls, *parts: Gaussians) -> Gaussians:
        """The Gaussians of ``parts``, in order."""
        return cls(**{name: torch.cat([getattr(p, name) for p in parts]) for name in cls.field_names()})

    def select(self, keep: torch.Tensor) -> Gaussians:
        """The Gaussians where the boolean (N,) mask ``keep`` is true (or at integer indices)."""
        return Gaussians(**{k: v[keep] for k, v in self.tensors().items()})


def _nearest_neighbour_scale(xyz: np.ndarray, k: int = 3) -> np.ndarray:
    """(P,) root mean squared distance to the ``k`` nearest other points, as 3D-GS initialises scales."""
    if len(xyz) < 2:
        return np.full(len(xyz), 0.01)
    k = min(k, len(xyz) - 1)
    dist, _ = cKDTree(xyz).query(xyz, k=k + 1)
    return np.sqrt(np.maximum((dist[:, 1:] ** 2).mean(axis=1), 1e-7))


def gaussians_from_points(
    xyz: np.ndarray,
    rgb: np.ndarray,
    *,
    initial_opacity: float,
    seed: int = 0,
) -> Gaussians:
    """Initial Gaussians at SfM points, as 3D-GS does it.

    Args:
        xyz: (P, 3) point positions.
        rgb: (P, 3) uint8 colours.
        initial_opacity: opacity of every new Gaussian.
        seed: seeds the small random object features.

    Returns:
        P isotropic Gaussians, sized by the distance to their three nearest neighbours,
        with the points' colours as DC, no view dependence and object features ~ U(0, 0.01).
    """
    n = len(xyz)
    scale = _nearest_neighbour_scale(np.asarray(xyz, np.float64))
    gen = torch.Generator().manual_seed(seed)
    return Gaussians(
        means=torch.as_tensor(xyz, dtype=torch.float32),
        log_scales=torch.log(torch.as_tensor(scale, dtype=torch.float32))[:, None].repeat(1, 3),
        quats=torch.tensor([1.0, 0.0, 0.0, 0.0]).repeat(n, 1),
        opacity_logits=torch.logit(torch.full((n,), initial_opacity)),
        sh_dc=rgb_to_sh_dc(torch.as_tensor(rgb, dtype=torch.float32) / 255.0),
        sh_rest=torch.zeros(n, num_coeffs(MAX_DEGREE) - 1, 3),
        obj_feat=0.01 * torch.rand(n, OBJ_FEAT_DIM, generator=gen),
    )


def random_points(center: np.ndarray, radius: float, count: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """``count`` random points (uniform in a cube of half-size ``radius`` around ``center``)
    with random colours, for scenes that have no SfM points: xyz (count, 3), rgb (count, 3) uint8."""
    rng = np.random.default_rng(seed)
    xyz = center + rng.uniform(-radius, radius, size=(count, 3))
    return xyz, rng.integers(0, 256, size=(count, 3), dtype=np.uint8)
