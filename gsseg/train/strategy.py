"""Adaptive density control of 3D-GS as a strategy beside the trainer (as gsplat's
``DefaultStrategy``): between steps it gathers the view-space positional gradient of every
Gaussian; on its schedule it clones small Gaussians and splits large ones where that
gradient is high, prunes transparent and oversized ones, and resets the opacities."""

from __future__ import annotations

from dataclasses import dataclass, field

import torch

from gsseg.model.gaussians import Gaussians
from gsseg.render import RenderOutput
from gsseg.render.projection import quat_to_rotmat
from gsseg.train.config import Schedule
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
        # Masked by torch.where rather than indexed: no index list, so no wait for the GPU.
        self.grad_sum += torch.where(visible, ndc.norm(dim=-1), 0.0)
        self.count += visible
        self.max_radii = torch.maximum(self.max_radii, torch.where(visible, radii.float(), 0.0))


@dataclass(frozen=True)
class DensifyOptions:
    """The thresholds of 3D-GS's adaptive density control.

    Attributes:
        grad_threshold: mean NDC positional gradient over which a Gaussian is densified.
        percent_dense: the size, as a share of ``extent``, that tells a clone (smaller) from
            a split (larger).
        prune_opacity: opacity under which a Gaussian is pruned.
        extent: the scene's scale (:attr:`gsseg.run.record.RunRecord.extent`).
        max_gaussians: densification adds no Gaussian past this count.
        split_shrink: a split's two children are the parent's size divided by this.
        prune_screen_radius: with ``prune_large``, Gaussians seen larger than this many pixels
            (radius) are pruned.
        prune_world_share: with ``prune_large``, Gaussians wider than this share of ``extent``
            are pruned.
    """

    grad_threshold: float
    percent_dense: float
    prune_opacity: float
    extent: float
    max_gaussians: int
    split_shrink: float = 1.6
    prune_screen_radius: float = 20.0
    prune_world_share: float = 0.1


def densify_and_prune(
    opt: GaussianOptimizer, stats: DensifyStats, options: DensifyOptions, prune_large: bool, generator: torch.Generator
) -> None:
    """One densification step; ``prune_large`` also removes Gaussians larger on screen or in
    the scene than ``options`` allow (3D-GS does that after the first opacity reset)."""
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
        children.log_scales = torch.log(s.scales / options.split_shrink).repeat(2, 1)
        grown = Gaussians(
            **{
                k: torch.cat([a, b])
                for (k, a), b in zip(g.select(clone).tensors().items(), children.tensors().values())
            }
        )
    else:
        grown = g.select(clone)
    opt.append(grown)
    now = opt.gaussians.detach()
    prune = now.opacities < options.prune_opacity
    prune[: len(g)] |= split  # split parents are replaced by their children
    if prune_large:
        radii = torch.cat([stats.max_radii, stats.max_radii.new_zeros(len(grown))])
        prune |= (radii > options.prune_screen_radius) | (
            now.scales.max(dim=1).values > options.prune_world_share * options.extent
        )
    opt.keep(~prune)
    fresh = DensifyStats.zeros(len(opt), stats.count.device)
    stats.grad_sum, stats.count, stats.max_radii = fresh.grad_sum, fresh.count, fresh.max_radii


@dataclass
class DensifyStrategy:
    """When densification, pruning and opacity resets happen, and the statistics they use.

    The trainer calls :meth:`after_backward` once the loss of a step has been
    back-propagated and :meth:`after_step` once the optimisers have stepped.
    """

    schedule: Schedule
    options: DensifyOptions
    seed: int
    stats: DensifyStats = field(default=None)  # type: ignore[assignment]

    def start(self, n: int, device: torch.device | str) -> None:
        """Empty statistics for ``n`` Gaussians."""
        self.stats = DensifyStats.zeros(n, device)

    def after_backward(self, step: int, out: RenderOutput, width: int, height: int) -> None:
        """Gather the statistics of the view just rendered at ``step``."""
        if step < self.schedule.densify_until and out.means2d.grad is not None:
            with torch.no_grad():
                self.stats.update(out.means2d.grad, out.radii, width, height)

    def after_step(self, step: int, opt: GaussianOptimizer) -> None:
        """Densify and prune, then reset opacities, when ``step`` is due."""
        s = self.schedule
        if s.densify_from < step < s.densify_until and step % s.densify_every == 0:
            gen = torch.Generator(self.stats.count.device).manual_seed(self.seed * 1_000_003 + step)
            densify_and_prune(opt, self.stats, self.options, step > s.opacity_reset_every, gen)
        if s.resets_opacity_at(step):
            opacities = torch.clamp_max(opt.gaussians.opacities.detach(), 0.01)
            opt.reset("opacity_logits", torch.logit(opacities))

    def state_dict(self) -> dict:
        return {"grad_sum": self.stats.grad_sum, "count": self.stats.count, "max_radii": self.stats.max_radii}

    def load_state_dict(self, state: dict) -> None:
        self.stats = DensifyStats(state["grad_sum"], state["count"], state["max_radii"])
