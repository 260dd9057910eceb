"""Intervals of a difference and a ratio of two weighted means on one sample.

For :mod:`avrisk.rare.paired`: ``p_A = mean(w a)`` and ``p_B = mean(w b)``
from the same weighted sample. The difference ``mean(w (b - a))`` has the
paired standard error of its terms; the ratio Fieller's interval
(:func:`fieller_interval`), the covariance of the two means in it. With no
discordant sample (``a = b`` throughout) both fall back to a bound from the
union's effective hits (:func:`discordance_bound`), never of zero width.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import stats

from avrisk.rare.families.base import FloatArray
from avrisk.rare.final_stage import CONFIDENCE
from avrisk.rare.results import GammaEstimate, jsonable
from avrisk.rare.weights import kish_ess

__all__ = [
    "DISCORDANCE_BOUND",
    "Z_ONE_SIDED",
    "Z_TWO_SIDED",
    "Contrast",
    "difference_contrast",
    "discordance_bound",
    "fieller_interval",
    "ratio_contrast",
]

#: Interval descriptions of :class:`Contrast`.
PAIRED_NORMAL = (
    "normal approximation of the paired weighted mean (CLT over the one "
    "weighted sample both versions share)"
)
FIELLER = (
    "Fieller's interval for the ratio of the two correlated weighted means "
    "(their covariance from the one weighted sample both versions share)"
)
#: Appended to an interval's description when its terms are controlled.
CONTROLLED = "the proposal's mixture components as control variates"
DISCORDANCE_BOUND = (
    "bound of a discordant side with no sample (B failing and A not, or the "
    "reverse): the zero-hit bound of its share of the union's effective hits, "
    "times the union's upper bound"
)


@dataclass(frozen=True)
class Contrast:
    """A difference or a ratio of ``p_B`` and ``p_A``, with its intervals.

    Attributes
    ----------
    value : float
        The estimate (``inf`` or NaN for a ratio over ``p_A = 0``).
    stderr : float
        Its standard error (delta method for a ratio); 0 with no discordant
        sample.
    ci : tuple of float
        Two-sided interval at level ``confidence``.
    lower, upper : float
        One-sided bounds at level ``confidence`` each (``P(true < lower) <=
        1 - confidence``): what a one-sided test reads (a CI gate).
    confidence : float
    interval : str
        How the intervals were computed, in words.
    """

    value: float
    stderr: float
    ci: tuple[float, float]
    lower: float
    upper: float
    confidence: float = CONFIDENCE
    interval: str = ""

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (non-finite floats become ``None``)."""
        return jsonable(dataclasses.asdict(self))


def _z(one_sided: float) -> float:
    """The standard normal quantile of one-sided level ``one_sided``."""
    return float(stats.norm.ppf(one_sided))


#: Normal quantiles of the two-sided interval and of the one-sided bounds.
Z_TWO_SIDED = _z(0.5 + CONFIDENCE / 2)
Z_ONE_SIDED = _z(CONFIDENCE)


def discordance_bound(
    log_w: FloatArray, union: np.ndarray, union_upper: float
) -> float:
    """Upper bound of ``P(A xor B)`` when no sample of the union is discordant.

    Parameters
    ----------
    log_w : ndarray of shape (n,)
        Log-weights of the sample.
    union : ndarray of bool, shape (n,)
        Samples in ``A or B``.
    union_upper : float
        Upper end of the union's two-sided interval (a one-sided bound at
        ``(1 + CONFIDENCE) / 2``).

    Returns
    -------
    float
        ``union_upper (1 - alpha^(1 / m))``, ``m`` the Kish ESS of the union's
        hits and ``alpha = (1 - CONFIDENCE) / 2``: the exact bound of a share
        seen 0 times in ``m`` draws, at the same one-sided level as
        ``union_upper``, so that both hold together at ``CONFIDENCE``.
        ``union_upper`` itself without a hit.

    Examples
    --------
    >>> # 0.1 (1 - 0.025^(1/4)): 4 equally weighted hits, none discordant
    >>> round(discordance_bound(np.zeros(4), np.ones(4, bool), 0.1), 4)
    0.0602
    """
    m = kish_ess(log_w[union])
    if m <= 0.0:
        return float(union_upper)
    alpha = (1.0 - CONFIDENCE) / 2.0
    return float(union_upper * -math.expm1(math.log(alpha) / m))


def fieller_interval(
    means: tuple[float, float], cov: FloatArray, z: float
) -> tuple[float, float]:
    """Fieller's interval of ``mean_b / mean_a``, two correlated means, in ``[0, inf]``.

    The set of ``R >= 0`` with ``(mean_b - R mean_a)^2 <= z^2 Var(mean_b - R
    mean_a)``, ``Var = v_bb - 2 R v_ab + R^2 v_aa``: exact for normal means.
    Bounded when ``mean_a`` is more than ``z`` standard errors above 0;
    otherwise it reaches ``inf`` (and starts at 0 unless ``mean_b`` is more
    than ``z`` standard errors above 0). Its ends at ``z`` for a one-sided
    level are the one-sided bounds at that level.

    Parameters
    ----------
    means : (float, float)
        ``mean_a``, ``mean_b``.
    cov : ndarray of shape (2, 2)
        Covariance matrix of the two means (not of single terms).
    z : float
        Normal quantile.

    Examples
    --------
    >>> lo, hi = fieller_interval((1.0, 2.0), np.diag([0.01, 0.01]), 1.96)
    >>> round(lo, 3), round(hi, 3)
    (1.626, 2.534)
    """
    a, b = means
    z2 = z * z
    quad = float(a * a - z2 * cov[0, 0])
    half = float(a * b - z2 * cov[0, 1])
    const = float(b * b - z2 * cov[1, 1])
    disc = max(half * half - quad * const, 0.0)
    if quad > 0.0:
        low, high = (half - math.sqrt(disc)) / quad, (half + math.sqrt(disc)) / quad
        return max(low, 0.0), max(high, 0.0)
    if const <= 0.0:  # neither mean clearly above 0
        return 0.0, math.inf
    # quad <= 0 < const: positive at 0, it falls below 0 past its one
    # positive root (the roots' product const / quad is negative)
    if quad < 0.0:
        return (half - math.sqrt(disc)) / quad, math.inf
    return (const / (2.0 * half) if half > 0.0 else 0.0), math.inf


def difference_contrast(
    terms: tuple[FloatArray, FloatArray],
    scale: float,
    unseen: tuple[float, float],
    ddof: int = 1,
) -> Contrast:
    """``p_B - p_A`` from the scaled terms ``w a`` and ``w b`` (times ``scale``).

    The paired normal interval of ``mean(w (b - a))``, widened below by
    ``unseen[0]`` and above by ``unseen[1]``: the bounds of ``P(A, not B)``
    and ``P(B, not A)`` where no such sample was drawn (0 where one was), so
    that a side the sample never saw is bounded, not taken for 0. ``ddof``
    above 1: the terms are controlled
    (:func:`~avrisk.rare.mixture_controls.controlled_terms`) and their spread
    loses the fit's degrees of freedom.
    """
    d = (terms[1] - terms[0]) * scale
    value = float(d.mean())
    se = float(d.std(ddof=ddof) / math.sqrt(d.size))
    down, up = unseen
    return Contrast(
        value,
        se,
        (value - Z_TWO_SIDED * se - down, value + Z_TWO_SIDED * se + up),
        value - Z_ONE_SIDED * se - down,
        value + Z_ONE_SIDED * se + up,
        CONFIDENCE,
        _described(PAIRED_NORMAL, unseen, ddof > 1),
    )


def ratio_contrast(
    terms: tuple[FloatArray, FloatArray],
    a: GammaEstimate,
    unseen: tuple[float, float],
    ddof: int = 1,
) -> Contrast:
    """``p_B / p_A`` from the scaled terms, ``a`` the estimate of ``p_A``.

    Fieller's interval, widened as :func:`difference_contrast` widens the
    difference's, divided by ``p_A``'s lower bound (``p_B / p_A = 1 + (p_B -
    p_A) / p_A``). With no discordant sample at all Fieller's interval is
    the point 1, and the widening alone makes it. ``ddof`` as for
    :func:`difference_contrast`.
    """
    wa, wb = terms
    n = wa.size
    mean_a, mean_b = float(wa.mean()), float(wb.mean())
    if mean_a > 0.0:
        value = mean_b / mean_a
        se = float((wb - value * wa).std(ddof=ddof) / math.sqrt(n) / mean_a)
    else:
        value, se = (math.inf if mean_b > 0.0 else math.nan), math.inf
    cov = np.cov(np.stack([wa, wb]), ddof=ddof) / n
    low, high = fieller_interval((mean_a, mean_b), cov, Z_TWO_SIDED)
    lower, upper = fieller_interval((mean_a, mean_b), cov, Z_ONE_SIDED)
    down, up = (_over(u, a.ci[0]) for u in unseen)
    return Contrast(
        value,
        se,
        (max(low - down, 0.0), high + up),
        max(lower - down, 0.0),
        upper + up,
        CONFIDENCE,
        _described(FIELLER, unseen, ddof > 1),
    )


def _over(bound: float, a_low: float) -> float:
    """A bound on ``p_B - p_A`` as one on ``p_B / p_A - 1``, over ``p_A``'s low end."""
    if bound == 0.0:
        return 0.0
    return bound / a_low if a_low > 0.0 else math.inf


def _described(
    interval: str, unseen: tuple[float, float], controlled: bool = False
) -> str:
    """``interval``, its controls and the widening by ``unseen``, where they are."""
    if controlled:
        interval = f"{interval}, with {CONTROLLED}"
    if not any(unseen):
        return interval
    return f"{interval}, widened by the {DISCORDANCE_BOUND}"
