"""Confidence intervals for a probability.

* :func:`clopper_pearson` -- exact binomial interval; never narrower than it
  should be, and with zero hits it is ``(0, 1 - (alpha/2)^(1/n))``: an honest
  upper bound instead of ``p = 0``.
* :func:`wilson` -- score interval; shorter, close to nominal coverage.
* :func:`normal_interval` -- ``p_hat +- z stderr`` for importance-sampling
  estimates, clipped to ``[0, 1]``.
"""

from __future__ import annotations

import numpy as np
from scipy import stats


def _z(level: float) -> float:
    if not 0.0 < level < 1.0:
        raise ValueError(f"confidence level must be in (0, 1); got {level}")
    return float(stats.norm.ppf(0.5 + level / 2.0))


def clopper_pearson(k: int, n: int, level: float = 0.95) -> tuple[float, float]:
    """Exact two-sided interval for ``k`` successes in ``n`` Bernoulli trials."""
    _z(level)
    if n <= 0 or not 0 <= k <= n:
        raise ValueError(f"need 0 <= k <= n and n > 0; got k={k}, n={n}")
    tail = (1.0 - level) / 2.0
    low = 0.0 if k == 0 else float(stats.beta.ppf(tail, k, n - k + 1))
    high = 1.0 if k == n else float(stats.beta.ppf(1.0 - tail, k + 1, n - k))
    return low, high


def wilson(k: int, n: int, level: float = 0.95) -> tuple[float, float]:
    """Wilson score interval for ``k`` successes in ``n`` Bernoulli trials."""
    z = _z(level)
    if n <= 0 or not 0 <= k <= n:
        raise ValueError(f"need 0 <= k <= n and n > 0; got k={k}, n={n}")
    p = k / n
    denom = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    return max(0.0, float(centre - half)), min(1.0, float(centre + half))


def normal_interval(
    p: float, stderr: float, level: float = 0.95
) -> tuple[float, float]:
    """``p +- z stderr`` clipped to ``[0, 1]``."""
    z = _z(level)
    return max(0.0, p - z * stderr), min(1.0, p + z * stderr)
