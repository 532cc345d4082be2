"""Adaptive density control of 3D-GS: clone small Gaussians and split large ones where the
view-space positional gradient is high; prune transparent and oversized ones."""

from __future__ import annotations

from dataclasses import dataclass

import torch

from gsseg.gaussians import Gaussians
from gsseg.render.projection import quat_to_rotmat
from gsseg.train.optim import GaussianOptimizer


@dataclass
class DensifyStats:
    """Per-Gaussian statistics gathered between densification steps: the summed norm of the
    NDC-space positional gradient (N,), how often each Gaussian was visible (N,), and its
    largest screen radius (N,)."""

    grad_sum: torch.Tensor
    count: torch.Tensor
    max_radii: torch.Tensor

    @classmethod
    def zeros(cls, n: int, device: torch.device | str = "cpu") -> DensifyStats:
        return cls(*(torch.zeros(n, device=device) for _ in range(3)))

    def update(self, means2d_grad: torch.Tensor, radii: torch.Tensor, width: int, height: int) -> None:
        """Add one view: ``means2d_grad`` (N, 2) in pixels, converted to NDC units as 3D-GS measures it."""
        visible = radii > 0
        ndc = means2d_grad.reshape(-1, 2) * means2d_grad.new_tensor([0.5 * width, 0.5 * height])
        self.grad_sum[visible] += ndc[visible].norm(dim=-1)
        self.count[visible] += 1
        self.max_radii[visible] = torch.maximum(self.max_radii[visible], radii[visible].float())


@dataclass(frozen=True)
class DensifyOptions:
    grad_threshold: float
    percent_dense: float
    prune_opacity: float
    extent: float
    max_gaussians: int


def densify_and_prune(opt: GaussianOptimizer, stats: DensifyStats, options: DensifyOptions,
                      prune_large: bool, generator: torch.Generator) -> None:
    """One densification step; ``prune_large`` also removes Gaussians over 20 px on screen or
    wider than 10% of the scene (3D-GS does that after the first opacity reset)."""
    g = opt.gaussians.detach()
    grads = stats.grad_sum / stats.count.clamp_min(1)
    scales = g.scales.max(dim=1).values
    big = scales > options.percent_dense * options.extent
    hot = grads >= options.grad_threshold
    # A clone or a split (two children replacing the parent) adds one Gaussian each; over the
    # budget, the largest gradients are densified first.
    budget = max(options.max_gaussians - len(opt), 0)
    if int(hot.sum()) > budget:
        hottest = torch.topk(torch.where(hot, grads, -1.0), budget).indices
        hot = torch.zeros_like(hot)
        hot[hottest] = True
    clone, split = hot & ~big, hot & big

    if split.any():
        s = g.select(split)
        samples = torch.randn(2, len(s), 3, generator=generator, device=s.means.device) * s.scales
        offsets = (quat_to_rotmat(s.quats) @ samples[..., None]).squeeze(-1)  # (2, n, 3)
        children = Gaussians(**{k: torch.cat([v, v]) for k, v in s.tensors().items()})
        children.means = (s.means + offsets).reshape(-1, 3)
        children.log_scales = torch.log(s.scales / 1.6).repeat(2, 1)
        grown = Gaussians(**{k: torch.cat([a, b]) for (k, a), b in
                             zip(g.select(clone).tensors().items(), children.tensors().values())})
    else:
        grown = g.select(clone)
    opt.append(grown)
    now = opt.gaussians.detach()
    prune = now.opacities < options.prune_opacity
    prune[: len(g)] |= split  # split parents are replaced by their children
    if prune_large:
        radii = torch.cat([stats.max_radii, stats.max_radii.new_zeros(len(grown))])
        prune |= (radii > 20) | (now.scales.max(dim=1).values > 0.1 * options.extent)
    opt.keep(~prune)
    fresh = DensifyStats.zeros(len(opt), stats.count.device)
    stats.grad_sum, stats.count, stats.max_radii = fresh.grad_sum, fresh.count, fresh.max_radii
