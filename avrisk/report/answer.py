"""The one answer a report or a terminal leads with, and whether to trust it.

A run's ``summary.json`` holds an estimate at every threshold with the
estimator's own diagnostics; :func:`threshold_trust` reads them into ``ok`` or
``caution`` with the reasons by the engine's one rule for every method
(:mod:`avrisk.rare.trust`), in a scenario's words; :func:`headline` picks
the answer among one or more runs and says it in one sentence, with its time
base: ``p`` is per rollout, one rollout being ``horizon`` seconds of driving
from a situation drawn from P0.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from avrisk.rare.estimator import estimator_class
from avrisk.rare.results import SearchConvergence, jsonable
from avrisk.rare.trust import Trust, Wording, estimate_trust

SECONDS_PER_HOUR = 3600.0


#: How a scenario's reasons name its measure and samples.
SCENARIO_WORDING = Wording("min TTC", " s", "rollout")


def main_threshold(summary: Mapping[str, Any]) -> dict[str, Any]:
    """The ``by_gamma`` entry of a summary at its own threshold ``gamma``."""
    est = summary["estimate"]
    return next(g for g in est["by_gamma"] if g["gamma"] == est["gamma"])


def threshold_trust(summary: Mapping[str, Any], threshold: Mapping[str, Any]) -> Trust:
    """The engine's one trust rule (:mod:`avrisk.rare.trust`) at one threshold.

    Parameters
    ----------
    summary : mapping
        The run's ``summary.json``.
    threshold : mapping
        One entry of its ``estimate.by_gamma``.
    """
    estimator = estimator_class(summary["method"])
    return estimate_trust(estimator, summary["estimate"], threshold, SCENARIO_WORDING)


def search_sentence(search: SearchConvergence) -> str:
    """:meth:`SearchConvergence.sentence` of a search on the minimum TTC [s]."""
    return search.sentence(SCENARIO_WORDING.measure, SCENARIO_WORDING.unit)


def search_remark(summary: Mapping[str, Any], trust: Trust) -> str | None:
    """How a run's search ended, unless that is among ``trust``'s reasons.

    :func:`search_sentence` of the estimator's
    :meth:`~avrisk.rare.estimator.Estimator.convergence`; None for an
    estimator that does not search, or where the sentence is a reason of the
    run's ``trust`` (:func:`run_trust`), which says it already.
    """
    est = summary["estimate"]
    search = estimator_class(summary["method"]).convergence(est, est["gamma"])
    if search is None:
        return None
    sentence = search_sentence(search)
    return None if sentence in trust.reasons else sentence


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
