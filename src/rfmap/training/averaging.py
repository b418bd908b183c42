"""Polyak averaging of a model's weights during training (``--ema DECAY``)."""
from __future__ import annotations

import torch

__all__ = ["WeightAverage"]


class WeightAverage:
    r"""An exponential moving average of a model's parameters (Polyak averaging).

    After the ``t``-th optimiser step (``t = 1, 2, ...`` from the start of the run)

    .. math:: \bar w \leftarrow \bar w + (1 - \beta_t)(w - \bar w), \qquad
              \beta_t = \min\!\left(\beta, \frac{1 + t}{10 + t}\right),

    the usual warm-up of the decay, so that the average soon forgets the starting weights.  With ``beta = 0.999``
    it spans about the last thousand steps.  Buffers (none in the shipped networks, which normalise by groups) are
    taken from the model as they are.

    Parameters
    ----------
    model : torch.nn.Module
        The model being trained (not a DistributedDataParallel wrapper).
    decay : float
        ``beta`` in ``(0, 1)``.
    """

    def __init__(self, model: torch.nn.Module, decay: float):
        if not 0.0 < decay < 1.0:
            raise ValueError(f"the weight-average decay must lie in (0, 1), got {decay}")
        self.decay = float(decay)
        self.names = [n for n, _ in model.named_parameters()]
        self.params = [p for _, p in model.named_parameters()]
        self.shadow = [p.detach().clone() for p in self.params]
        self.updates = 0

    @torch.no_grad()
    def update(self) -> None:
        """Fold the model's current parameters into the average (call after every optimiser step)."""
        self.updates += 1
        beta = min(self.decay, (1.0 + self.updates) / (10.0 + self.updates))
        torch._foreach_lerp_(self.shadow, [p.detach() for p in self.params], 1.0 - beta)

    def averaged_state(self, model: torch.nn.Module) -> dict:
        """``model.state_dict()`` with the averaged parameters in place of the trained ones (detached copies)."""
        state = {k: v.detach().clone() for k, v in model.state_dict().items()}
        for name, avg in zip(self.names, self.shadow):
            state[name] = avg.detach().clone()
        return state

    def state_dict(self) -> dict:
        return {"updates": self.updates, "shadow": {n: t.detach().cpu() for n, t in zip(self.names, self.shadow)}}

    def load_state_dict(self, state: dict) -> None:
        self.updates = int(state["updates"])
        for name, t in zip(self.names, self.shadow):
            t.copy_(state["shadow"][name])
