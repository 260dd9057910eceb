"""The engine's one entry point: estimate ``P0(f(X) <= gamma)`` by any method.

:func:`estimate` runs a registered estimator (:mod:`avrisk.rare.estimator`) by
its name on a batched black box ``f`` under a base distribution ``base``. The
method's settings come as keyword arguments, as a settings object, or both;
the other keywords, shared by every method, are documented here once. The
functions named after the methods (:func:`~avrisk.rare.cross_entropy.cross_entropy`,
:func:`~avrisk.rare.naive_mc.naive_mc` ...) are this call with the method's name
filled in.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

from avrisk.rare.estimation_context import EstimationContext
from avrisk.rare.estimator import (
    Estimator,
    EstimatorSettings,
    estimator_class,
    run_estimator,
)
from avrisk.rare.evaluation import Evaluator
from avrisk.rare.families.base import ExponentialFamily
from avrisk.rare.problem import BatchFunction, RareEventProblem, threshold_list
from avrisk.rare.results import Estimate
from avrisk.rare.stages import BatchCache, BatchRecorder
from avrisk.rare.stopping import StoppingRule

__all__ = ["estimate"]


def estimate(
    method: str | Estimator[Any, Any],
    f: BatchFunction,
    base: ExponentialFamily,
    gamma: float,
    *,
    settings: EstimatorSettings | None = None,
    seed: int = 0,
    gamma_test: Sequence[float] | float = (),
    batch_size: int | None = None,
    callback: Callable[[Any, Any], None] | None = None,
    on_batch: BatchRecorder | None = None,
    cache: BatchCache | None = None,
    evaluator: Evaluator | None = None,
    stopping: StoppingRule | None = None,
    directional_audit: bool = True,
    **overrides: Any,
) -> Estimate:
    """Estimate ``P0(f(X) <= gamma)`` with the estimator ``method``.

    Parameters
    ----------
    method : str or Estimator
        A registered name (:func:`~avrisk.rare.estimator.estimator_names`):
        ``"naive"`` (naive Monte Carlo), ``"ce"`` (cross-entropy importance
        sampling), ``"defensive"`` (CE with a defensive final stage),
        ``"mixture"`` (mixture CE, for several failure regions),
        ``"splitting"`` (subset simulation with pCN moves) or
        ``"splitting_is"`` (importance sampling from splitting's particles);
        or an estimator built already (then without ``settings`` or
        ``overrides``).
    f : callable
        Batched black box, ``(n, D)`` float64 array to ``(n,)`` values; low
        means the event.
    base : ExponentialFamily
        ``P0``. Its search box constrains the CE proposals; splitting needs
        it to map to standard normals (``to_standard_normal``).
    gamma : float
        Threshold of the event ``f <= gamma``.
    settings : EstimatorSettings, optional
        The method's settings object (``CESettings``, ``SplittingSettings``
        ...; default: its defaults).
    seed : int, default=0
        Run seed; the same seed gives the same result whatever ``batch_size``
        and ``evaluator``.
    gamma_test : float or sequence of float, default=()
        Further thresholds estimated from the same samples.
    batch_size : int or None, default=None
        Largest number of rows per call of ``f``.
    callback : callable, optional
        ``callback(info, state)`` after each step of the search (a CE
        iteration, a splitting level): progress display, checkpoints.
    on_batch : callable, optional
        Called with each evaluated :class:`~avrisk.rare.stages.StageBatch`,
        of every stage (a samples table, a progress bar).
    cache : callable, optional
        ``cache(stage, chunk)`` returns a recorded batch of an interrupted
        run with the same settings, or ``None``: resuming replays the record
        (:mod:`avrisk.rare.stages`).
    evaluator : Evaluator, optional
        Where ``f`` runs (:mod:`avrisk.rare.evaluation`); default this process.
    stopping : StoppingRule, optional
        Ends a sampling stage early (:mod:`avrisk.rare.stopping`); the
        result's ``stopped_by`` says what ended it.
    directional_audit : bool, default=True
        Whether a method that searches is checked by random rays where ``X``
        has at most 8 dimensions (:mod:`avrisk.rare.directional_audit`:
        ``details["directional"]``, its 6,144 calls in ``n_evals``; a failure
        region the search missed makes the trust rule say caution). False
        compares methods at exactly their own calls.
    **overrides
        The method's settings by name (CE: ``rho``, ``n_per_iter``,
        ``n_iter``, ``n_final`` ...; splitting: ``n_particles``, ``p0`` ...),
        in place of those of ``settings``.

    Returns
    -------
    Estimate
        The estimate of every threshold; ``history`` holds one info per
        search step, ``details`` what the method adds (splitting's levels).

    Raises
    ------
    UnknownComponentError
        If ``method`` is not registered (also a ``KeyError``; the message
        lists the known names).
    TypeError
        If a keyword is none of the method's settings, or ``settings`` is
        another method's.
    ValueError
        If a setting is invalid (the message names it).
    SplittingError
        For splitting methods whose levels cannot reach ``gamma``.

    Examples
    --------
    >>> import numpy as np
    >>> from scipy.stats import norm
    >>> from avrisk.rare import FixedCovNormal, estimate
    >>> base = FixedCovNormal(np.zeros(2), cov=np.eye(2))
    >>> f = lambda x: 5.0 - x.sum(axis=1) / np.sqrt(2)   # P(f <= 0) = Phi(-5)
    >>> est = estimate("ce", f, base, 0.0, rho=0.1, n_per_iter=2000, n_iter=8,
    ...                n_final=10_000, seed=0)
    >>> bool(abs(est.p / norm.sf(5.0) - 1) < 0.1)
    True

    Two failure regions, ``|x1| >= 4``, one on each side, found by mixture CE:

    >>> f = lambda x: 4.0 - np.abs(x[:, 0])   # P(f <= 0) = 2 Phi(-4)
    >>> est = estimate("mixture", f, base, 0.0, n_components=2, n_per_iter=2000,
    ...                n_iter=6, n_final=10_000, seed=0)
    >>> sorted(round(float(c.mean[0])) for c in est.proposal.components)
    [-4, 4]
    >>> bool(abs(est.p / (2 * norm.sf(4.0)) - 1) < 0.1)
    True
    """
    if isinstance(method, str):
        cls = estimator_class(method)
        estimator = cls(cls.Settings.overridden(settings, "estimate", **overrides))
    elif settings is not None or overrides:
        raise TypeError(
            "estimate() takes settings only with a method's name, not with an "
            "estimator built already"
        )
    else:
        estimator = method
    problem = RareEventProblem(base, f, gamma, threshold_list(gamma_test), batch_size)
    context = EstimationContext(seed, evaluator, on_batch, cache, stopping=stopping)
    return run_estimator(
        estimator,
        problem,
        context,
        callback=callback,
        directional_audit=directional_audit,
    )
