"""The one answer a report or a terminal leads with, and whether to trust it.

A run's ``summary.json`` holds an estimate at every threshold with the
estimator's own diagnostics: hits, effective hits (ESS), the Pareto tail index
of the hits' weights, rollouts that failed to evaluate. :func:`trust_at` reads
them into ``ok`` or ``caution`` with the reasons (the rules of
:func:`avrisk.rare.final_stage.is_reliable`, no other), and
:func:`threshold_trust` adds whether the estimator's search converged there
(a cross-entropy search that never reached the threshold, or did not hold
it: :class:`avrisk.rare.results.SearchConvergence`); :func:`headline` picks
the answer among one or more runs and says it in one sentence, with its time
base: ``p`` is per rollout, one rollout being ``horizon`` seconds of driving
from a situation drawn from P0.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from avrisk.rare.estimator import estimator_class
from avrisk.rare.final_stage import MIN_RELIABLE_ESS
from avrisk.rare.results import SearchConvergence, jsonable
from avrisk.rare.weights import MAX_RELIABLE_PARETO_K

SECONDS_PER_HOUR = 3600.0


@dataclass(frozen=True)
class Trust:
    """Whether an estimate's interval can be taken at its word.

    Attributes
    ----------
    reasons : tuple of str
        Why not, one clause each; empty when the diagnostics raise nothing.
    """

    reasons: tuple[str, ...] = ()

    @property
    def ok(self) -> bool:
        """No diagnostic raised a doubt."""
        return not self.reasons

    @property
    def word(self) -> str:
        """``"ok"`` or ``"caution"``."""
        return "ok" if self.ok else "caution"

    def __str__(self) -> str:
        """``"ok"`` or ``"caution (reason; reason)"``."""
        return self.word if self.ok else f"caution ({'; '.join(self.reasons)})"


def trust_at(threshold: Mapping[str, Any], weighted: bool) -> Trust:
    """What an estimate's own diagnostics say of it, at one threshold.

    Parameters
    ----------
    threshold : mapping
        One entry of a summary's ``estimate.by_gamma`` (``n_hits``, ``ess``,
        ``pareto_k``, ``n_failed``; the last two may be missing or None in
        older summaries).
    weighted : bool
        Whether the estimator weights its samples (importance sampling): then
        effective hits and the weights' tail decide, else the hits alone.

    Returns
    -------
    Trust
        Caution for no hit, fewer than ``MIN_RELIABLE_ESS`` (effective) hits,
        hit weights with a heavy tail (Pareto k above
        ``MAX_RELIABLE_PARETO_K``), or rollouts that failed to evaluate.
    """
    hits = int(threshold["n_hits"])
    ess = threshold.get("ess") or 0.0
    tail = threshold.get("pareto_k")
    reasons = []
    if hits == 0:
        reasons.append("no rollout reached the threshold: the interval is a bound only")
    elif not weighted and hits < MIN_RELIABLE_ESS:
        reasons.append(
            f"only {hits} {'hit' if hits == 1 else 'hits'}: relative standard error "
            f"about {1 / math.sqrt(hits):.0%}"
        )
    elif weighted and ess < MIN_RELIABLE_ESS:
        reasons.append(
            f"only {ess:.1f} effective hits: a few weights dominate, so the "
            "standard error is unreliable"
        )
    elif weighted and tail is not None and tail > MAX_RELIABLE_PARETO_K:
        reasons.append(
            f"the hits' weights have a heavy tail (Pareto k = {tail:.2f} > "
            f"{MAX_RELIABLE_PARETO_K:g}): the standard error is unreliable, likely "
            "too small"
        )
    failed = int(threshold.get("n_failed") or 0)
    if failed:
        reasons.append(
            f"{failed:,} rollouts failed to evaluate: p counts them safe, the "
            "interval reaches counting them dangerous"
        )
    return Trust(tuple(reasons))


def main_threshold(summary: Mapping[str, Any]) -> dict[str, Any]:
    """The ``by_gamma`` entry of a summary at its own threshold ``gamma``."""
    est = summary["estimate"]
    return next(g for g in est["by_gamma"] if g["gamma"] == est["gamma"])


def threshold_trust(summary: Mapping[str, Any], threshold: Mapping[str, Any]) -> Trust:
    """:func:`trust_at` one threshold of a run, and whether its search converged there.

    Parameters
    ----------
    summary : mapping
        The run's ``summary.json``.
    threshold : mapping
        One entry of its ``estimate.by_gamma``.

    Returns
    -------
    Trust
        The search's failure to converge first (:meth:`Estimator.convergence
        <avrisk.rare.estimator.Estimator.convergence>`), then the final
        stage's own reasons.
    """
    estimator = estimator_class(summary["method"])
    own = trust_at(threshold, estimator.weighted)
    search = estimator.convergence(summary["estimate"], threshold["gamma"])
    if search is None or search.converged:
        return own
    return Trust((search_sentence(search), *own.reasons))


def search_sentence(search: SearchConvergence) -> str:
    """:meth:`SearchConvergence.sentence` of a search on the minimum TTC [s]."""
    return search.sentence("min TTC", " s")


def run_trust(summary: Mapping[str, Any]) -> Trust:
    """:func:`threshold_trust` at a run's main threshold."""
    return threshold_trust(summary, main_threshold(summary))


@dataclass(frozen=True)
class Headline:
    """The answer of one or more runs, as a report leads with it.

    Attributes
    ----------
    label : str
        The run it comes from (its method, e.g. ``"cross-entropy"``).
    gamma : float
        Threshold on the minimum TTC [s].
    p : float
        ``P0(min TTC <= gamma)`` per rollout.
    ci : tuple of float
        95% interval of ``p``.
    n_rollouts : int
        Rollouts of that run, every stage.
    horizon_s : float or None
        Length of one rollout [s]: the time base of ``p`` (None: unknown, a
        black box that is not a scenario).
    trust : Trust
    chosen_from : int
        Runs it was chosen from (1: the only one).
    """

    label: str
    gamma: float
    p: float
    ci: tuple[float, float]
    n_rollouts: int
    horizon_s: float | None
    trust: Trust
    chosen_from: int = 1

    @property
    def per_hour(self) -> float | None:
        """Dangerous events per hour of driving, ``p * 3600 / horizon`` [1/h].

        An approximation: it treats an hour of driving as ``3600 / horizon``
        independent rollouts, each from a situation drawn from P0. None
        without a horizon.
        """
        if self.horizon_s is None:
            return None
        return self.p * SECONDS_PER_HOUR / self.horizon_s

    @property
    def event(self) -> str:
        """``"P(min TTC <= 0.1 s) per 10-s rollout from P0"``."""
        per = "" if self.horizon_s is None else f"{self.horizon_s:g}-s "
        return f"P(min TTC <= {self.gamma:g} s) per {per}rollout from P0"

    def sentence(self) -> str:
        """The answer in one line, trust and its reasons included."""
        lo, hi = self.ci
        return (
            f"{self.event} = {self.p:.3g} (95% CI {lo:.2g} to {hi:.2g}), "
            f"method {self.label}, {self.n_rollouts:,} rollouts; trust: {self.trust}"
        )

    def time_base(self) -> str:
        """What ``p`` is per, and per hour of driving (an approximation)."""
        if self.per_hour is None:
            return "p is per rollout, from a situation drawn from P0."
        return (
            f"p is per rollout: {self.horizon_s:g} s of driving from a situation "
            f"drawn from P0. Per hour of driving that is about {self.per_hour:.2g} "
            f"events (p x 3600 / {self.horizon_s:g}; an approximation that treats "
            "an hour as independent rollouts)."
        )

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (non-finite numbers become None)."""
        return jsonable(
            {
                "event": self.event,
                "run": self.label,
                "gamma_s": self.gamma,
                "p": self.p,
                "ci": list(self.ci),
                "n_rollouts": self.n_rollouts,
                "horizon_s": self.horizon_s,
                "per_hour_approx": self.per_hour,
                "trust": self.trust.word,
                "reasons": list(self.trust.reasons),
                "chosen_from": self.chosen_from,
            }
        )


def headline(
    runs: Sequence[tuple[str, Mapping[str, Any]]], horizon_s: float | None
) -> Headline:
    """The answer of ``runs``: the narrowest 95% interval among the trusted ones.

    Parameters
    ----------
    runs : sequence of (label, summary)
        Complete runs of one scenario at the same main threshold (a run and,
        in a comparison, naive Monte Carlo and a reference), first the one
        under test.
    horizon_s : float or None
        The scenario's rollout length [s] (None: unknown).

    Returns
    -------
    Headline
        From the run whose main-threshold interval is narrowest among those
        whose :func:`run_trust` is ok; the first run when none is.
    """
    scored = [(label, summary, run_trust(summary)) for label, summary in runs]
    trusted = [r for r in scored if r[2].ok]

    def width(run: tuple[str, Mapping[str, Any], Trust]) -> float:
        lo, hi = run[1]["estimate"]["ci"]
        return hi - lo

    label, summary, trust = min(trusted, key=width) if trusted else scored[0]
    est = summary["estimate"]
    return Headline(
        label=label,
        gamma=est["gamma"],
        p=est["p"],
        ci=(est["ci"][0], est["ci"][1]),
        n_rollouts=est["n_evals"],
        horizon_s=horizon_s,
        trust=trust,
        chosen_from=len(scored),
    )
