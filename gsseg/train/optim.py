"""Adam over the Gaussian tensors, with the surgery densification needs: keeping a subset
of Gaussians and appending new ones, moment estimates included."""

from __future__ import annotations

import torch

from gsseg.model.gaussians import Gaussians
from gsseg.train.config import LearningRates


class GaussianOptimizer:
    """One Adam parameter group per Gaussian field (``means``, ``log_scales``, ...)."""

    def __init__(self, gaussians: Gaussians, lr: LearningRates, extent: float):
        self.params = {k: torch.nn.Parameter(v.detach().clone()) for k, v in gaussians.tensors().items()}
        groups = [
            {"params": [p], "name": k, "lr": getattr(lr, k) * (extent if k == "means" else 1.0)}
            for k, p in self.params.items()
        ]
        self.adam = torch.optim.Adam(groups, lr=0.0, eps=1e-15)

    @property
    def gaussians(self) -> Gaussians:
        return Gaussians(**self.params)

    def __len__(self) -> int:
        return self.params["means"].shape[0]

    def step(self) -> None:
        self.adam.step()
        self.adam.zero_grad(set_to_none=True)

    def set_lr(self, name: str, lr: float) -> None:
        for group in self.adam.param_groups:
            if group["name"] == name:
                group["lr"] = lr

    def _rebuild(self, edit) -> None:
        """Replace every parameter by ``edit(name, tensor, is_state)`` and carry Adam's moments."""
        for group in self.adam.param_groups:
            name, old = group["name"], group["params"][0]
            new = torch.nn.Parameter(edit(name, old.detach(), False))
            state = self.adam.state.pop(old, None)
            if state:
                state["exp_avg"] = edit(name, state["exp_avg"], True)
                state["exp_avg_sq"] = edit(name, state["exp_avg_sq"], True)
                self.adam.state[new] = state
            group["params"][0] = new
            self.params[name] = new

    def keep(self, mask: torch.Tensor) -> None:
        """Keep the Gaussians where the boolean (N,) ``mask`` is true."""
        self._rebuild(lambda name, t, is_state: t[mask])

    def append(self, new: Gaussians) -> None:
        """Append Gaussians; their Adam moments start at zero."""
        extra = new.tensors()
        self._rebuild(
            lambda name, t, is_state: torch.cat(
                [t, torch.zeros_like(extra[name]) if is_state else extra[name].detach().to(t)]
            )
        )

    def reset(self, name: str, values: torch.Tensor) -> None:
        """Overwrite one field and zero its moments (the 3D-GS opacity reset)."""
        self._rebuild(lambda n, t, is_state: t if n != name else (torch.zeros_like(t) if is_state else values))

    def state_dict(self) -> dict:
        return {"params": {k: v.detach() for k, v in self.params.items()}, "adam": self.adam.state_dict()}

    def load_state_dict(self, state: dict) -> None:
        for group in self.adam.param_groups:
            name = group["name"]
            p = torch.nn.Parameter(state["params"][name].clone())
            group["params"][0] = p
            self.params[name] = p
        self.adam.state.clear()
        self.adam.load_state_dict(state["adam"])
