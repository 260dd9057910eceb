"""Whether an estimate's interval can be taken at its word: one rule for every method.

An estimate carries its own diagnostics at every threshold: hits, effective
hits (ESS), the Pareto tail index of the hits' weights, samples that failed to
evaluate; and its estimator may know more of how it got there (a
cross-entropy search that reached the threshold and drifted back, or never
reached it, :meth:`Estimator.convergence
<avrisk.rare.estimator.Estimator.convergence>`, :func:`search_doubts`;
independent replicates of a splitting search that disagree, or a level held
by a handful of particles, :meth:`Estimator.doubts
<avrisk.rare.estimator.Estimator.doubts>`). :func:`estimate_trust` reads them
all into ``ok`` or ``caution`` with the reasons, in the words of the problem
(:class:`Wording`: ``f`` and samples for a black box, the minimum TTC and
rollouts for a scenario).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from avrisk.rare.directional_audit import directional_doubts, directional_table
from avrisk.rare.estimator import DiagnosticTable
from avrisk.rare.final_stage import MIN_RELIABLE_ESS
from avrisk.rare.results import SearchConvergence
from avrisk.rare.weights import MAX_RELIABLE_PARETO_K

__all__ = [
    "GENERIC",
    "Trust",
    "Wording",
    "estimate_diagnostics",
    "estimate_trust",
    "search_doubts",
    "trust_at",
]


@dataclass(frozen=True)
class Wording:
    """How reasons name the problem's measure and samples.

    Attributes
    ----------
    measure : str
        What ``f`` is called (``"f"``, ``"min TTC"``).
    unit : str
        Follows its values (``""``, ``" s"``).
    sample : str
        One evaluation of ``f`` (``"sample"``, ``"rollout"``).
    """

    measure: str = "f"
    unit: str = ""
    sample: str = "sample"

    def event(self, gamma: float) -> str:
        """``"f <= 0.1"``, ``"min TTC <= 0.1 s"``."""
        return f"{self.measure} <= {gamma:g}{self.unit}"


#: A black box's words.
GENERIC = Wording()


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


def trust_at(
    threshold: Mapping[str, Any], weighted: bool, wording: Wording = GENERIC
) -> Trust:
    """What an estimate's own diagnostics say of it, at one threshold.

    Parameters
    ----------
    threshold : mapping
        One entry of an estimate's ``by_gamma`` as a dictionary (``n_hits``,
        ``ess``, ``pareto_k``, ``n_failed``; the last two may be missing or
        None in older summaries).
    weighted : bool
        Whether the estimator weights its samples (importance sampling): then
        effective hits and the weights' tail decide, else the hits alone.
    wording : Wording, default=GENERIC

    Returns
    -------
    Trust
        Caution for no hit, fewer than ``MIN_RELIABLE_ESS`` (effective) hits,
        hit weights with a heavy tail (Pareto k above
        ``MAX_RELIABLE_PARETO_K``), or samples that failed to evaluate.
    """
    hits = int(threshold["n_hits"])
    ess = threshold.get("ess") or 0.0
    tail = threshold.get("pareto_k")
    reasons = []
    if hits == 0:
        reasons.append(
            f"no {wording.sample} reached {wording.event(threshold['gamma'])}: "
            "the interval is a bound only"
        )
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
            f"{failed:,} {wording.sample}s failed to evaluate: p counts them safe, "
            "the interval reaches counting them dangerous"
        )
    return Trust(tuple(reasons))


def estimate_trust(
    estimator: Any,
    estimate: Mapping[str, Any],
    threshold: Mapping[str, Any],
    wording: Wording = GENERIC,
) -> Trust:
    """The one trust rule: the search, the estimator's doubts, the diagnostics.

    Parameters
    ----------
    estimator : Estimator class
        The estimator that made it (``convergence``, ``doubts``, ``weighted``).
    estimate : mapping
        ``Estimate.to_dict()`` (a summary's ``estimate``).
    threshold : mapping
        One entry of its ``by_gamma``.
    wording : Wording, default=GENERIC

    Returns
    -------
    Trust
        The search's failure to converge first (where :func:`search_doubts`),
        then the estimator's own doubts, then the check by rays
        (:func:`~avrisk.rare.directional_audit.directional_doubts`), then
        :func:`trust_at`'s reasons.
    """
    gamma = threshold["gamma"]
    others = [
        *estimator.doubts(estimate, gamma),
        *directional_doubts(estimate, gamma),
        *trust_at(threshold, estimator.weighted, wording).reasons,
    ]
    search = estimator.convergence(estimate, gamma)
    if search_doubts(search, others):
        others.insert(0, search.sentence(wording.measure, wording.unit))
    return Trust(tuple(others))


def search_doubts(search: SearchConvergence | None, others: Sequence[str]) -> bool:
    """Whether a search's end is a reason of an estimate's trust.

    A search that reached ``gamma`` and drifted back had not settled: a doubt
    of its own. One that never reached it leaves a proposal aimed at a less
    rare event, and its final sample is importance sampling all the same:
    its interval rests on that sample's weights, which :func:`trust_at`
    judges (effective hits, their tail) and the check by rays complements,
    so the search's shortfall is said beside their reasons, as their likely
    cause, and is no doubt of its own where they raise none.

    Parameters
    ----------
    search : SearchConvergence or None
        The estimator's :meth:`~avrisk.rare.estimator.Estimator.convergence`.
    others : sequence of str
        The estimate's other reasons.
    """
    if search is None or search.converged:
        return False
    return search.reached_at is not None or bool(others)


def estimate_diagnostics(
    estimator: Any, estimate: Mapping[str, Any]
) -> list[DiagnosticTable]:
    """The tables behind the rule: the estimator's own, then the check by rays.

    ``estimate`` is a summary's (``Estimate.to_dict()``); the check's table is
    there only where it ran (:func:`~avrisk.rare.directional_audit.directional_table`).
    """
    return [*estimator.diagnostics(estimate), *directional_table(dict(estimate))]
