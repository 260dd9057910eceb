"""Model-based GAIL's discriminator: a reward that is differentiable in the rollout.

MGAIL (Baram et al. 2017, the paper's generator training) trains a
discriminator ``D`` to tell human transitions from the policy's, as GAIL
does, but improves the policy by back-propagating ``D``'s reward through a
differentiable model of the dynamics instead of by a policy gradient. Our
simulator's functional step is differentiable, so the model is the simulator
itself (:func:`avrisk.learning.training.closed_loop.differentiable_replay`). One
round of :func:`~avrisk.learning.training.closed_loop.closed_loop_finetune` with
``adversarial_weight > 0``::

    replay a minibatch of training windows with gradient
    x_t = transition_features(simulated follower)      (v, gap, dv, a_prev, a)
    D step(s): logistic loss, human transitions (label 1) vs x_t.detach() (0)
    policy loss += -adversarial_weight * mean_t softplus(logit D(x_t))
                   (GAIL's reward -log(1 - D), D's weights held fixed)

The discriminator's inputs, network and logistic training are those of
:mod:`avrisk.learning.imitation.discriminator`
(:func:`~avrisk.learning.imitation.discriminator.transition_features`),
standardised by the human statistics.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import Tensor

from avrisk.learning.imitation.discriminator import (
    human_transitions,
    mlp,
    train_discriminator,
)
from avrisk.learning.replay import CarFollowingWindows

__all__ = ["Discriminator"]


class Discriminator:
    """``logit D(x)`` on transition features, with its optimiser and human data.

    Parameters
    ----------
    human : CarFollowingWindows
        Recorded windows whose transitions are the positives (training
        windows only).
    hidden : int
        Width of the two tanh hidden layers.
    lr : float
        Adam learning rate.
    seed : int
        Initial weights and the human rows drawn per update.
    """

    def __init__(
        self, human: CarFollowingWindows, hidden: int, lr: float, seed: int
    ) -> None:
        x = human_transitions(human)
        self.mean, self.scale = x.mean(0), x.std(0).clamp_min(1e-6)
        self.human = (x - self.mean) / self.scale
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(seed)
            self.net = mlp(x.shape[-1], hidden)
        self.optimizer = torch.optim.Adam(self.net.parameters(), lr=lr)
        self.generator = torch.Generator().manual_seed(seed)

    def logit(self, x: Tensor) -> Tensor:
        """``logit D(x)`` of raw features ``x`` of shape (..., 5); shape (...)."""
        return self.net((x - self.mean.to(x)) / self.scale.to(x)).squeeze(-1)

    def reward(self, x: Tensor) -> Tensor:
        """GAIL's reward ``-log(1 - D(x)) = softplus(logit D(x))``, shape (...).

        Differentiable in ``x``; ``D``'s own weights get no gradient.
        """
        for p in self.net.parameters():
            p.requires_grad_(False)
        try:
            return F.softplus(self.logit(x))
        finally:
            for p in self.net.parameters():
                p.requires_grad_(True)

    def update(self, policy: Tensor, epochs: int, batch: int) -> float:
        """Logistic steps on policy rows ``policy`` (N, 5) vs human rows.

        Returns
        -------
        float
            Accuracy after the update on the policy rows and as many human rows.
        """
        x = ((policy.detach() - self.mean) / self.scale).float()
        return train_discriminator(
            self.net,
            self.human,
            x,
            self.optimizer,
            epochs=epochs,
            batch=batch,
            generator=self.generator,
        )
