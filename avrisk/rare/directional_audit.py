"""A check for failure regions a search missed, by rays: directional simulation.

A search (the levels of subset simulation, a cross-entropy proposal) can
follow one failure mechanism and never see another that holds most of ``p``:
on RP110 (two regions holding 99.1% and 0.9% of ``p``) the levels pass a
step where the large region holds about 1% of the set, and a run whose
particles all leave it reports ``0.009 p`` with healthy diagnostics. Nothing
that reads only the search's own samples can see it, and a second search of
the same kind (the proposal audit, :mod:`avrisk.rare.proposal_audit`) misses
it as often.

Directional simulation (Bjerager 1988; Ditlevsen and Madsen, *Structural
Reliability Methods*, ch. 9) does not search. In the standard-normal space of
``P0`` (:meth:`~avrisk.rare.families.base.ExponentialFamily.from_standard_normal`),
``z = R A`` with ``A`` uniform on the unit sphere and ``R^2 ~ chi^2_D``
independent of it, so

    p = E_A[ P(R in {r : f(r A) <= gamma}) ],

and each ray's inner probability is a difference of ``chi^2_D`` tails at the
radii where ``f`` crosses ``gamma`` along it. ``RAYS`` directions, each
evaluated at ``RADII`` evenly spaced radii out to where the ``chi^2_D`` tail
falls below ``TAIL``, give an estimate of ``p`` whose spread comes from the
directions alone; every direction is drawn, so no region is followed and none
is left. Crossings between two radii are placed by linear interpolation of
``f - gamma`` (no extra calls); a failure interval thinner than the radii's
spacing can be missed, which only makes the check quieter. The rays reach
further out than any search; a point where ``f`` fails to evaluate there
counts safe (the record says how many), and never stops a run whose estimate
is already made.

Its error grows with the dimension and with how narrow the event's cone of
directions is: with 256 rays it is under half of ``p`` on most of the exact
suite's problems in two to seven dimensions (up to twice ``p`` on a few) and
several times ``p`` in ten, where the share of directions that reach a region
rare enough to matter is too small. So it runs only where ``D <= MAX_DIM``,
after the estimator's own stages (the estimate is the same with or without
it), on every method that searches (naive sampling cannot miss a region: its
interval is the binomial one).

The run says caution when the check's low end, its estimate minus ``Z`` of
its standard errors, lies above the upper end of the estimate's interval: the
interval cannot hold what the rays found. The check never raises an estimate
and never lowers one; it is a doubt, not an answer.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np
from scipy import stats

from avrisk.rare.diagnostic_table import DiagnosticTable
from avrisk.rare.estimation_context import EstimationContext
from avrisk.rare.problem import SAMPLE_CHUNK, RareEventProblem, chunk_rng
from avrisk.rare.results import Estimate, doubting_check

__all__ = [
    "MAX_DIM",
    "RADII",
    "RAYS",
    "STAGE",
    "Z",
    "audit_calls",
    "directional_audit",
    "directional_doubts",
    "directional_table",
    "with_directional_audit",
]

#: Largest dimension of ``X`` the check runs in (module docstring).
MAX_DIM = 8
#: Directions drawn uniformly on the unit sphere of standard-normal space.
RAYS = 256
#: Radii evaluated along each direction, evenly spaced in ``(0, r_max]``.
RADII = 24
#: ``r_max`` is where the ``chi^2_D`` tail of ``R^2`` falls to this probability:
#: beyond it lies less than any probability the check could tell from zero.
TAIL = 1e-14
#: Standard errors below its estimate that the check's low end lies.
Z = 3.0
#: The stage its points are recorded as: after any estimator's own stages.
STAGE = 1 << 20


def audit_calls(estimator: Any, dim: int) -> int:
    """Calls of ``f`` the check adds to a run of ``estimator`` on ``X`` in ``R^dim``.

    ``RAYS * RADII`` where it runs: an estimator that searches (its class's
    ``searches``, True unless it says otherwise) and ``dim <= MAX_DIM``; else 0.
    """
    return (
        RAYS * RADII if getattr(estimator, "searches", True) and dim <= MAX_DIM else 0
    )


def _radii(dim: int) -> np.ndarray:
    """The radii of every ray, shape (RADII,): evenly spaced out to ``r_max``."""
    r_max = math.sqrt(stats.chi2.isf(TAIL, dim))
    return np.linspace(0.0, r_max, RADII + 1)[1:]


def _ray_probabilities(margin: np.ndarray, radii: np.ndarray, dim: int) -> np.ndarray:
    """``P(R in {r : f(r A) <= gamma})`` for each ray, shape (rays,).

    ``margin`` is ``f - gamma`` at ``radii`` along each ray, shape (rays,
    RADII) (``+inf`` where ``f`` failed to evaluate: counted safe). The ray's
    side at radius 0 is taken to be that of its first radius; each change of
    side between two radii is placed by linear interpolation of the margin,
    and the ray's probability is the sum of ``chi^2_D`` tails, added where it
    enters the event and taken away where it leaves it.
    """
    r = np.concatenate([[0.0], radii])
    g = np.concatenate([margin[:, :1], margin], axis=1)
    inside = g <= 0
    ray, k = np.nonzero(inside[:, 1:] != inside[:, :-1])
    g0, g1 = g[ray, k], g[ray, k + 1]
    finite = np.isfinite(g0) & np.isfinite(g1)
    t = np.where(finite, g0 / np.where(finite, g0 - g1, 1.0), 0.5)
    crossing = r[k] + np.clip(t, 0.0, 1.0) * (r[k + 1] - r[k])
    tail = stats.chi2.sf(crossing**2, dim)
    entering = inside[ray, k + 1]
    probability = np.where(inside[:, 0], 1.0, 0.0)
    np.add.at(probability, ray, np.where(entering, tail, -tail))
    return np.clip(probability, 0.0, 1.0)


def directional_audit(
    problem: RareEventProblem, context: EstimationContext, estimate: Estimate
) -> dict[str, Any]:
    """Estimate ``p`` along ``RAYS`` random rays and compare with ``estimate``.

    Parameters
    ----------
    problem : RareEventProblem
        ``X`` in ``R^D``; its base maps standard normals to ``X``.
    context : EstimationContext
        The run's: the rays' directions and points are those of stage
        ``STAGE`` of its seed, recorded and replayed like any chunk.
    estimate : Estimate
        The estimator's, at ``problem.gamma``.

    Returns
    -------
    dict
        The record (``details["directional"]``): ``rays``, ``radii``,
        ``n_calls``, ``n_failed`` (points counted safe), ``p`` and ``stderr``
        (the rays' mean and its standard error), ``low`` (``p - Z stderr``),
        ``rays_in_event`` (rays that reach the event) and ``doubt`` (whether
        ``low`` lies above the estimate's interval).
    """
    dim = problem.base.dim
    rng = chunk_rng(context.seed, STAGE, 0)
    directions = rng.standard_normal((RAYS, dim))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    radii = _radii(dim)
    z = (radii[None, :, None] * directions[:, None, :]).reshape(-1, dim)
    x = problem.base.from_standard_normal(z)
    # Rays reach further out than any search (radius r_max), where an f may
    # fail to evaluate: those points count safe and are reported, and never
    # stop a run whose estimate is already made.
    context = context._replace(max_failed_share=1.0)
    values, failed = [], []
    for chunk, start in enumerate(range(0, len(x), SAMPLE_CHUNK)):
        v, bad = context.evaluate(
            problem, x[start : start + SAMPLE_CHUNK], STAGE, chunk
        )
        values.append(v)
        failed.append(bad)
    f, bad = np.concatenate(values), np.concatenate(failed)
    margin = np.where(bad, np.inf, f - problem.gamma).reshape(RAYS, RADII)
    per_ray = _ray_probabilities(margin, radii, dim)
    p = float(per_ray.mean())
    stderr = float(per_ray.std(ddof=1) / math.sqrt(RAYS))
    low = p - Z * stderr
    main = estimate.by_gamma[problem.gamma]
    return {
        "rays": RAYS,
        "radii": RADII,
        "n_calls": int(len(x)),
        "n_failed": int(np.count_nonzero(bad)),
        "p": p,
        "stderr": stderr,
        "low": low,
        "rays_in_event": int(np.count_nonzero(per_ray > 0)),
        "doubt": bool(low > main.ci[1]),
    }


def with_directional_audit(
    estimator: Any,
    estimate: Estimate,
    problem: RareEventProblem,
    context: EstimationContext,
) -> Estimate:
    """``estimate`` with the check's record and calls, where it runs (else as is).

    A run whose stopping rule caps its calls (``max_rollouts``) takes the
    check only within the cap; else its record says it was skipped and why.
    """
    calls = audit_calls(estimator, problem.base.dim)
    if not calls:
        return estimate
    cap = context.stopping.max_rollouts if context.stopping is not None else None
    if cap is not None and estimate.n_evals + calls > cap:
        record: dict[str, Any] = {
            "rays": RAYS,
            "skipped": f"its {calls:,} calls of f would pass the cap of {cap:,}",
        }
        return replace(
            estimate, details={**(estimate.details or {}), "directional": record}
        )
    record = directional_audit(problem, context, estimate)
    return replace(
        estimate,
        n_evals=estimate.n_evals + record["n_calls"],
        details={**(estimate.details or {}), "directional": record},
    )


def directional_doubts(estimate: dict[str, Any], gamma: float) -> tuple[str, ...]:
    """The check's doubt at the run's own ``gamma``, as a sentence (or none).

    ``estimate`` is a summary's ``estimate`` (:meth:`Estimate.to_dict`); one
    without the check, or asked of a test threshold, has none.
    """
    record = doubting_check(estimate, "directional", gamma)
    if record is None:
        return ()
    return (
        f"{record['rays']} random rays through P0 (directional simulation, no "
        f"search) put p at {record['p']:.3g}, at least {record['low']:.2g}, above "
        "the interval: a failure region the search missed",
    )


def directional_table(estimate: dict[str, Any]) -> list[DiagnosticTable]:
    """The check of a summary's ``estimate`` as a one-row table (none without it)."""
    record = (estimate.get("details") or {}).get("directional")
    if not record:
        return []
    if "skipped" in record:
        return [
            DiagnosticTable(
                "Rays: a check that searches nothing",
                ("rays", "verdict"),
                [(record["rays"], f"not run: {record['skipped']}")],
            )
        ]
    row = (
        record["rays"],
        record["n_calls"],
        record["rays_in_event"],
        record["p"],
        record["low"],
        "caution" if record["doubt"] else "ok",
    )
    return [
        DiagnosticTable(
            "Rays: a check that searches nothing",
            ("rays", "calls", "reach the event", "its p", "its low end", "verdict"),
            [row],
            note=(
                "After the estimate, f is evaluated along random rays from the "
                "centre of P0 in its standard-normal space (directional "
                f"simulation, {record['radii']} radii a ray). Every direction is "
                "drawn, so a failure region the search never reached is found "
                f"in proportion to its probability. Its low end is its p less "
                f"{Z:g} standard errors; above the estimate's interval, the run "
                "says caution. It runs where X has at most "
                f"{MAX_DIM} dimensions."
            ),
        )
    ]
