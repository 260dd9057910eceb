"""Turn the final stage's samples into per-threshold estimates."""

from __future__ import annotations

import warnings
from collections.abc import Callable
from dataclasses import replace
from typing import NamedTuple

import numpy as np

from avrisk.rare.families.base import FloatArray
from avrisk.rare.intervals import clopper_pearson, normal_interval, wilson
from avrisk.rare.results import GammaEstimate
from avrisk.rare.stages import StageResult
from avrisk.rare.weights import (
    MAX_RELIABLE_PARETO_K,
    kish_ess,
    pareto_tail_index,
    weighted_mean_and_stderr,
)

CONFIDENCE = 0.95

BINOMIAL_INTERVALS = {"clopper-pearson": clopper_pearson, "wilson": wilson}

#: The ``interval`` of :class:`GammaEstimate`, by how it was computed.
INTERVAL_NAMES = {
    "clopper-pearson": "exact binomial (Clopper-Pearson)",
    "wilson": "binomial score (Wilson)",
    "normal": "normal approximation of the weighted mean (CLT; trusted while the "
    "hits' weights have Pareto k <= 0.7 and at least 10 effective hits)",
    "uninformative": "(0, 1): no hit, and the weights of unseen events are unknown",
}


#: Below this effective number of hits the standard error itself is unreliable.
MIN_RELIABLE_ESS = 10.0


def is_reliable(ess: float | None, pareto_k: float | None) -> bool:
    """Whether an importance-sampling standard error can be trusted.

    At least ``MIN_RELIABLE_ESS`` effective hits, and no heavy tail in the hits'
    weights (``pareto_k <= MAX_RELIABLE_PARETO_K``, or unknown). ``None``
    stands for a value missing from a summary.
    """
    heavy = pareto_k is not None and pareto_k > MAX_RELIABLE_PARETO_K
    return (ess or 0.0) >= MIN_RELIABLE_ESS and not heavy


class ZeroHitsWarning(UserWarning):
    """The importance-sampling stage saw no event: its interval is only ``(0, 1)``."""


class UnreliableEstimateWarning(UserWarning):
    """Few effective hits, or hit weights with a heavy tail (Pareto k > 0.7).

    A handful of weights dominate the estimate, or would in a larger sample;
    the standard error and the interval are computed from those same weights,
    so they cannot be trusted either.
    """


class Advice(NamedTuple):
    """What to change when a final stage's estimate is unreliable.

    Clauses for the warnings of :func:`importance_estimates`, in the setting
    names of the estimator that made the stage (a cross-entropy search
    raises ``n_per_iter``, subset simulation ``n_particles``).

    Attributes
    ----------
    no_hit : str
        No sample reached the threshold.
    degenerate : str
        Hits, but fewer than ``MIN_RELIABLE_ESS`` effective ones.
    heavy_tail : str
        The hits' weights have a heavy tail (Pareto k above 0.7).
    """

    no_hit: str
    degenerate: str
    heavy_tail: str


#: For a final stage whose proposal no estimator made (a script's own).
NEUTRAL_ADVICE = Advice(
    no_hit="raise n_final or move the proposal towards the event",
    degenerate="the proposal is degenerate: bring it closer to P0 given the event",
    heavy_tail="raise n_final and bring the proposal closer to P0 given the "
    "event, or compare runs with other seeds",
)


def bracket_failures(
    estimates: Callable[[FloatArray], dict[float, GammaEstimate]],
    values: FloatArray,
    failed: np.ndarray | None,
) -> dict[float, GammaEstimate]:
    """Estimates with failed samples counted safe, bracketed by counting them dangerous.

    Parameters
    ----------
    estimates : callable
        Per-threshold estimates from the values of every sample.
    values : ndarray of shape (n,)
        ``f`` (NaN allowed where ``failed``).
    failed : ndarray of bool, shape (n,), or None
        Samples whose evaluation failed (None: none).

    Returns
    -------
    dict of float to GammaEstimate
        ``p`` with the failed samples counted safe, ``p_if_failed_dangerous``
        with them counted dangerous, and ``ci`` from the low end of the first
        interval to the high end of the second.
    """
    if failed is None or not failed.any():
        return estimates(values)
    safe = estimates(np.where(failed, np.inf, values))
    with warnings.catch_warnings():  # the safe side has warned already
        warnings.simplefilter("ignore")
        dangerous = estimates(np.where(failed, -np.inf, values))
    n_failed = int(np.count_nonzero(failed))
    return {
        g: replace(
            est,
            ci=(est.ci[0], max(est.ci[1], dangerous[g].ci[1])),
            n_failed=n_failed,
            p_if_failed_dangerous=dangerous[g].p,
        )
        for g, est in safe.items()
    }


def binomial_estimates(
    values: FloatArray, thresholds: tuple[float, ...], interval: str = "clopper-pearson"
) -> dict[float, GammaEstimate]:
    """Naive Monte Carlo: hit fraction, binomial standard error and interval."""
    n = values.size
    out = {}
    for g in thresholds:
        k = int(np.count_nonzero(values <= g))
        p = k / n
        out[g] = GammaEstimate(
            gamma=g,
            p=p,
            stderr=float(np.sqrt(p * (1 - p) / n)),
            ci=BINOMIAL_INTERVALS[interval](k, n, CONFIDENCE),
            n_hits=k,
            ess=float(k),
            n_samples=n,
            confidence=CONFIDENCE,
            interval=INTERVAL_NAMES[interval],
        )
    return out


def importance_estimates(
    values: FloatArray,
    log_w: FloatArray,
    thresholds: tuple[float, ...],
    advice: Advice = NEUTRAL_ADVICE,
) -> dict[float, GammaEstimate]:
    """Importance sampling: ``mean(w 1{f <= g})``, its standard error, a normal CI.

    With zero hits the data bound nothing better than ``p <= 1`` (the weights of
    unseen events are unknown), so that is the interval reported. Zero hits,
    few effective hits and a heavy tail of the hits' weights are warned about
    at the first threshold, the run's ``gamma``
    (:attr:`~avrisk.rare.problem.RareEventProblem.thresholds`), each warning
    ending with the remedy ``advice`` gives: the proposal was made for that
    threshold. The other thresholds' diagnostics are in their estimates
    (``n_hits``, ``ess``, ``pareto_k``), for a table, not warnings.
    """
    out = {g: weighted_hits_estimate(log_w, values <= g, g) for g in thresholds}
    if thresholds:
        _warn_if_unreliable(out[thresholds[0]], advice)
    return out


def weighted_hits_estimate(
    log_w: FloatArray, hits: np.ndarray, gamma: float
) -> GammaEstimate:
    """``mean(w 1{hit})`` of one event, its standard error and diagnostics.

    Parameters
    ----------
    log_w : ndarray of shape (n,)
        Log-weights ``log p0 - log q`` of every sample of the stage.
    hits : ndarray of bool, shape (n,)
        The samples in the event (``f <= gamma``, or any other event of the
        same samples: one version failing and not the other).
    gamma : float
        The threshold the event is labelled with.

    Returns
    -------
    GammaEstimate
        The normal interval with hits; ``(0, 1)`` without (the weights of
        unseen events are unknown). No warning: see
        :func:`importance_estimates`.
    """
    k = int(np.count_nonzero(hits))
    p, se = weighted_mean_and_stderr(log_w, hits)
    return GammaEstimate(
        gamma=gamma,
        p=p,
        stderr=se,
        ci=normal_interval(p, se, CONFIDENCE) if k else (0.0, 1.0),
        n_hits=k,
        ess=kish_ess(log_w[hits]),
        n_samples=hits.size,
        confidence=CONFIDENCE,
        pareto_k=pareto_tail_index(log_w[hits]),
        interval=INTERVAL_NAMES["normal" if k else "uninformative"],
    )


def _warn_if_unreliable(est: GammaEstimate, advice: Advice) -> None:
    """Warn of zero hits, few effective hits or a heavy tail of weights in ``est``."""
    g, k, ess, tail = est.gamma, est.n_hits, est.ess, est.pareto_k
    if k == 0:
        warnings.warn(
            f"no sample of the final stage reached f <= {g:g}; the estimate is 0 "
            f"with the uninformative interval (0, 1): {advice.no_hit}",
            ZeroHitsWarning,
            stacklevel=4,
        )
    elif ess < MIN_RELIABLE_ESS:
        warnings.warn(
            f"f <= {g:g}: {k} hits but an effective number of only {ess:.1f}; "
            "a few weights dominate and the standard error is unreliable "
            f"({advice.degenerate})",
            UnreliableEstimateWarning,
            stacklevel=4,
        )
    elif tail > MAX_RELIABLE_PARETO_K:
        warnings.warn(
            f"f <= {g:g}: the hits' weights have a heavy tail (Pareto k = "
            f"{tail:.2f} > {MAX_RELIABLE_PARETO_K}); the standard error is "
            f"unreliable, likely too small ({advice.heavy_tail})",
            UnreliableEstimateWarning,
            stacklevel=4,
        )


def weighted_stage_estimates(
    stage: StageResult, thresholds: tuple[float, ...], advice: Advice
) -> dict[float, GammaEstimate]:
    """Importance-sampling estimates of a final stage, failed samples bracketed.

    :func:`importance_estimates` of the stage's values and log-weights per
    threshold, through :func:`bracket_failures`; ``advice``: the remedies of
    the estimator that made the stage.
    """
    return bracket_failures(
        lambda values: importance_estimates(values, stage.log_w, thresholds, advice),
        stage.values,
        stage.failed,
    )
