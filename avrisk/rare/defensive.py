"""Defensive mixtures: a proposal blended with the base distribution.

Importance sampling from ``q`` weighs each sample by ``p0(x) / q(x)``. Where
``q`` is thinner than ``p0`` (a Beta proposal with a shape above twice the
base's, a normal shifted away from a second failure region) those weights have
a heavy upper tail, or even infinite variance: the estimate is then dominated
by rare huge weights, and its sample standard error, computed from the same
weights, comes out too small. Sampling instead from the *defensive mixture*
(Hesterberg 1995)

    m(x) = (1 - lam) q(x) + lam p0(x)

bounds every weight by ``p0 / m <= 1 / lam``, so the variance is finite and at
most ``1 / lam`` times naive Monte Carlo's whatever ``q`` is, while keeping
most of ``q``'s gain where it fits (a fraction ``lam`` of the samples comes
from ``p0``).

References
----------
.. [1] T. Hesterberg, "Weighted average importance sampling and defensive
   mixture distributions", Technometrics 37(2), 1995.
.. [2] A. Owen, Y. Zhou, "Safe and effective importance sampling", JASA
   95(449), 2000.
"""

from __future__ import annotations

import math

import numpy as np

from avrisk.rare.families.base import ExponentialFamily, FloatArray

__all__ = ["DefensiveMixture", "check_defensive"]


def check_defensive(weight: float) -> float:
    """``weight`` as a float in ``[0, 1)``, else a ValueError naming it."""
    if not 0.0 <= weight < 1.0:
        raise ValueError(f"defensive must be in [0, 1); got {weight}")
    return float(weight)


class DefensiveMixture:
    """Sample from ``(1 - weight) proposal + weight base`` (see module docstring).

    Parameters
    ----------
    proposal, base : ExponentialFamily
        On the same space.
    weight : float
        Mixture weight ``lam`` of ``base``, in (0, 1).

    Examples
    --------
    >>> import numpy as np
    >>> from avrisk.rare import FixedCovNormal
    >>> base = FixedCovNormal(np.zeros(1), cov=np.eye(1))
    >>> far = FixedCovNormal(np.array([6.0]), cov=np.eye(1))
    >>> mix = DefensiveMixture(far, base, 0.1)
    >>> x = mix.sample(100_000, np.random.default_rng(0))
    >>> w = np.exp(base.log_prob(x) - mix.log_prob(x))  # p0 / m, mean 1
    >>> bool(w.max() <= 10.0), bool(abs(w.mean() - 1.0) < 0.03)
    (True, True)
    """

    def __init__(
        self, proposal: ExponentialFamily, base: ExponentialFamily, weight: float
    ) -> None:
        if not 0.0 < weight < 1.0:
            raise ValueError(f"weight must be in (0, 1); got {weight}")
        if proposal.dim != base.dim:
            raise ValueError(
                f"proposal and base differ in dimension: {proposal.dim} vs {base.dim}"
            )
        self.proposal = proposal
        self.base = base
        self.weight = weight

    @property
    def dim(self) -> int:
        """Dimension ``D`` of a sample."""
        return self.base.dim

    def sample(self, n: int, rng: np.random.Generator) -> FloatArray:
        """Draw ``n`` samples, shape (n, D).

        Component choices and both components' draws come from separate
        children of ``rng``, so row ``i`` does not depend on ``n`` (the engine's
        prefix consistency).
        """
        choose, from_q, from_p0 = rng.spawn(3)
        use_base = choose.random(n) < self.weight
        return np.where(
            use_base[:, None],
            self.base.sample(n, from_p0),
            self.proposal.sample(n, from_q),
        )

    def log_prob(self, x: FloatArray) -> FloatArray:
        """Log-density of the mixture, shape (n,)."""
        return np.logaddexp(
            math.log1p(-self.weight) + self.proposal.log_prob(x),
            math.log(self.weight) + self.base.log_prob(x),
        )
