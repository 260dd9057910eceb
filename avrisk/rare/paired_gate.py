"""A release gate: ``p_B / p_A`` against a margin, from a paired estimate."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

from avrisk.rare.final_stage import CONFIDENCE
from avrisk.rare.paired import PairedEstimate
from avrisk.rare.paired_intervals import Z_ONE_SIDED
from avrisk.rare.results import jsonable

__all__ = ["Verdict", "gate"]


@dataclass(frozen=True)
class Verdict:
    """A one-sided test of ``p_B / p_A`` against a margin (a release gate).

    Attributes
    ----------
    outcome : str
        ``"pass"``: the one-sided upper bound of ``p_B / p_A`` is at most
        ``max_ratio``; ``"fail"``: the one-sided lower bound is above it;
        ``"inconclusive"`` otherwise. Each bound at level ``confidence``.
    max_ratio : float
        The margin.
    lower, upper : float
        The one-sided bounds of the ratio.
    n_final_needed : int or None
        For an inconclusive verdict, the final-stage samples at which the
        bound on the side of the estimate would reach the margin if the
        estimate stayed where it is (:func:`_samples_to_decide`); None
        otherwise, or when no number would (an estimate at the margin, or
        an unbounded ratio).
    confidence : float
    """

    outcome: str
    max_ratio: float
    lower: float
    upper: float
    n_final_needed: int | None = None
    confidence: float = CONFIDENCE

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (non-finite floats become ``None``)."""
        return jsonable(dataclasses.asdict(self))


def gate(estimate: PairedEstimate, max_ratio: float) -> Verdict:
    """Pass, fail or inconclusive: ``p_B / p_A`` against ``max_ratio``.

    Parameters
    ----------
    estimate : PairedEstimate
    max_ratio : float
        Largest acceptable ``p_B / p_A`` (1: ``B`` no riskier than ``A``).
    """
    ratio = estimate.ratio
    lower, upper = ratio.lower, ratio.upper
    if upper <= max_ratio:
        return Verdict("pass", max_ratio, lower, upper)
    if lower > max_ratio:
        return Verdict("fail", max_ratio, lower, upper)
    return Verdict(
        "inconclusive", max_ratio, lower, upper, _samples_to_decide(estimate, max_ratio)
    )


def _samples_to_decide(estimate: PairedEstimate, max_ratio: float) -> int | None:
    """Final-stage samples at which the ratio's bound would clear ``max_ratio``.

    The bound on the estimate's side of the margin lies ``z s + u`` from it:
    ``s`` its standard error, which at ``k`` times the samples falls to ``s /
    sqrt(k)``, and ``u`` the rest (the bound of a discordant side with no
    sample, :mod:`avrisk.rare.paired_intervals`), which falls as ``u / k``
    (the zero-hit bound of a share of ``m`` effective hits is about ``3 /
    m``). The smallest ``k`` with ``z s / sqrt(k) + u / k <= |R - max_ratio|``
    solves a quadratic in ``1 / sqrt(k)``.
    """
    ratio = estimate.ratio
    gap = abs(ratio.value - max_ratio)
    side = ratio.upper if ratio.value < max_ratio else ratio.lower
    spread = abs(side - ratio.value)
    if gap == 0.0 or not math.isfinite(spread) or not math.isfinite(gap):
        return None
    sampled = min(Z_ONE_SIDED * ratio.stderr, spread)
    unseen = spread - sampled
    if unseen > 0.0:  # unseen t^2 + sampled t - gap = 0, t = 1 / sqrt(k)
        t = (math.sqrt(sampled**2 + 4.0 * unseen * gap) - sampled) / (2.0 * unseen)
    else:
        t = gap / sampled
    return math.ceil(estimate.a.n_samples / t**2)
