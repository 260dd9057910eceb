"""An independent check that an importance sampler's proposal samples all of the event.

A cross-entropy proposal (plain or mixture) sits where its search led. A
failure region the search never reached is a region its final stage never
draws, and so leaves no trace in the final stage's own diagnostics: on RP110
(two regions holding 99.1% and 0.9% of ``p``) CE reports ``0.009 p`` with an
ESS of 7,400 and a light tail. No check that reads only the proposal's draws
can see it; particles of the event found by another search can.

The audit is that other search: subset simulation (:mod:`avrisk.rare.splitting`,
``particles`` per level in its two replicates, no regrowth, no plateau
draws), run after the final stage on stages of its own, so its samples are
independent of the proposal's and the estimate is the same with or without
it. Its last sets' particles with ``f <= gamma`` are (correlated) draws of
``P0(. | f <= gamma)``, found without the proposal. For each one ``x``, the
weight ``w(x) = p0(x) / q(x)`` that the final stage's distribution ``q`` would
give it tells whether ``q`` draws there: ``q(x) = p0(x | F) p / w(x)``, so
``w(x) > n p_hat`` (``n`` final draws) means the final stage draws around
``x`` less than ``1 / n`` as often as the event's own law has mass there,
fewer than one draw in all of a region holding all of ``p``. Call such a
particle *uncovered*; ``k`` of the audit's ``m`` particles.

The share ``k / m`` estimates how much of the event's law lies where the
final stage draws nothing, and the audit's own estimate ``p_a`` (the
replicates' mean product) says how much probability that is: about ``k / m *
p_a``, missing from ``p_hat``. The run says caution when a low estimate of
that missing mass, ``(k - 2 sqrt(k)) / m`` (a Poisson lower bound of ``k``)
times the lower end of ``p_a``'s interval, added to ``p_hat``, lies above the
upper end of ``p_hat``'s interval: the interval cannot hold what the audit
found outside it. A region holding a sliver of ``p`` (RP110's 0.9%, the
audit's particles all in it) is then no doubt for an estimate whose interval
is wider than that sliver; a region holding half of ``p`` is.

The audit sees only what its own levels reach: a region both searches miss
stays unseen. An audit whose levels end above ``gamma``, or whose chains
stop moving, has nothing to say and says nothing (its record says why).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from avrisk.rare.estimation_context import EstimationContext
from avrisk.rare.estimator import DiagnosticTable
from avrisk.rare.problem import RareEventProblem
from avrisk.rare.results import Estimate, doubting_check
from avrisk.rare.splitting import SubsetSimulation
from avrisk.rare.splitting_levels import SplittingError
from avrisk.rare.splitting_settings import SplittingSettings

__all__ = [
    "audit_bound",
    "audit_doubts",
    "audit_proposal",
    "audit_settings",
    "audit_table",
]


def audit_settings(particles: int) -> SplittingSettings:
    """The audit's subset simulation: ``particles`` per level, no regrowth."""
    return SplittingSettings(n_particles=particles, regrow=0, plateau_draws=1)


def audit_bound(particles: int) -> int:
    """The most calls of ``f`` an audit with ``particles`` per level makes (0: none)."""
    return audit_settings(particles).bound(regrow=0) if particles else 0


def audit_proposal(
    sampled: Any,
    estimate: Estimate,
    n_final: int,
    problem: RareEventProblem,
    context: EstimationContext,
    *,
    particles: int,
    after_stage: int,
) -> dict[str, Any]:
    """Audit the final stage's distribution ``sampled`` (module docstring).

    Parameters
    ----------
    sampled : distribution
        What the final stage drew from (``log_prob`` of shape (m,)).
    estimate : Estimate
        The final stage's estimate (``p_hat`` and its interval at ``gamma``).
    n_final : int
        Draws of the final stage.
    problem : RareEventProblem
    context : EstimationContext
        The run's; the audit's stages follow ``after_stage``.
    particles : int
        Particles per level of the audit's subset simulation.
    after_stage : int
        The estimator's last stage before the audit.

    Returns
    -------
    dict
        The record (``details["audit"]``): ``particles`` (per level),
        ``n_calls``, ``reached`` (whether a replicate's levels reached
        ``gamma``), ``error`` (why not, or None); once reached, ``n_at_gamma``
        (``m``), ``n_uncovered`` (``k``), ``p`` and ``ci`` (the audit's own
        estimate), ``missed_low`` (the low estimate of the missing mass) and
        ``doubt`` (whether ``p_hat + missed_low`` is above ``p_hat``'s
        interval).
    """
    audit = SubsetSimulation(audit_settings(particles))
    state = audit.init(problem)
    state = state._replace(current=state.current._replace(n_stages=after_stage))
    record: dict[str, Any] = {"particles": particles, "reached": False, "error": None}
    try:
        while not audit.done(state):
            state, _ = audit.step(state, problem, context)
    except SplittingError as exc:  # chains that stopped moving: no particles
        record["error"] = str(exc)
    record["n_calls"] = state.current.n_evals
    reached = state.reached() if record["error"] is None else []
    if not reached:
        record["error"] = record["error"] or "its levels did not reach gamma"
        return record
    own = audit.finalize(state, problem, context).by_gamma[problem.gamma]
    z = np.concatenate(
        [r.z[r.sets[-1].flat <= problem.gamma] for r, _ in reached], axis=0
    )
    main = estimate.by_gamma[problem.gamma]
    m = len(z)
    if m and main.p > 0:
        x = problem.base.from_standard_normal(z)
        log_w = problem.base.log_prob(x) - sampled.log_prob(x)
        k = int(np.count_nonzero(log_w > math.log(n_final * main.p)))
    else:  # no particle at gamma, or a final stage with no hit: all uncovered
        k = m
    missed_low = max(k - 2.0 * math.sqrt(k), 0.0) / max(m, 1) * own.ci[0]
    record.update(
        reached=True,
        n_at_gamma=m,
        n_uncovered=k,
        p=own.p,
        ci=list(own.ci),
        missed_low=missed_low,
        doubt=bool(main.p > 0 and main.p + missed_low > main.ci[1]),
    )
    return record


def audit_doubts(estimate: dict[str, Any], gamma: float) -> tuple[str, ...]:
    """The audit's doubt at the run's own ``gamma``, as a sentence (or none).

    ``estimate`` is a summary's ``estimate`` (:meth:`Estimate.to_dict`); an
    estimate with no audit, or asked of a test threshold, has none.
    """
    record = doubting_check(estimate, "audit", gamma)
    if record is None:
        return ()
    share = record["n_uncovered"] / record["n_at_gamma"]
    return (
        f"an independent search (subset simulation) put {share:.0%} of its "
        f"{record['n_at_gamma']:,} particles of the event where the final stage "
        f"draws almost nothing: p is likely low by at least "
        f"{record['missed_low']:.2g}, beyond the interval (a failure region the "
        "search missed)",
    )


def audit_table(estimate: dict[str, Any]) -> list[DiagnosticTable]:
    """The audit of a summary's ``estimate`` as a one-row table (none without one)."""
    record = (estimate.get("details") or {}).get("audit")
    if not record:
        return []
    reached = record.get("reached")
    row = (
        record["particles"],
        record["n_calls"],
        record.get("n_at_gamma") if reached else None,
        record.get("n_uncovered") if reached else None,
        record.get("p") if reached else None,
        "caution" if record.get("doubt") else ("ok" if reached else record["error"]),
    )
    return [
        DiagnosticTable(
            "The audit: an independent search for the event",
            (
                "per level",
                "calls",
                "in the event",
                "hardly drawn",
                "its p",
                "verdict",
            ),
            [row],
            note=(
                "After the final stage, a small subset simulation looks for the "
                "event on its own, independently of the proposal (per level: its "
                "particles; calls: its calls of f; in the event: its particles "
                "with f <= gamma). Those the final stage would hardly ever draw "
                "(hardly drawn: a weight p0/q above n p) lie in a part of the "
                "event the search missed; their share times its own estimate of "
                "p is probability the estimate leaves out. The run says caution "
                "when that is more than the estimate's interval can hold."
            ),
        )
    ]
