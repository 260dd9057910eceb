"""Safety measures that are a minimum over time of an instantaneous value."""

from __future__ import annotations

import torch
from torch import Tensor

__all__ = ["RunningMin"]


class RunningMin:
    """``f`` = minimum over the simulated steps of ``instant(state_t)``.

    Subclasses define ``name``, ``tests_per_pair`` and ``instant``; this class
    folds the instants in (see :mod:`avrisk.sim.interfaces`), leaving a stopped
    rollout's value as it was at its last simulated step.
    """

    def init(self, value: Tensor) -> Tensor:
        """Running value from the instant at ``t = 0``, shape (B,)."""
        return value

    def update(self, carry: Tensor, value: Tensor, alive: Tensor) -> Tensor:
        """Fold in a new step's value where the rollout is still ``alive`` (B,)."""
        return torch.where(alive, torch.minimum(carry, value), carry)

    def finalize(self, carry: Tensor) -> Tensor:
        """``f`` of every rollout, shape (B,)."""
        return carry
