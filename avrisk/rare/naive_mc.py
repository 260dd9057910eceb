"""Naive Monte Carlo: the baseline every rare-event estimator is compared with.

    X_1..X_n ~ P0 i.i.d.;  p_hat = #{f(X_i) <= gamma} / n

It needs about ``1 / (p eps^2)`` calls of ``f`` for relative accuracy ``eps``.
The interval is exact binomial (Clopper-Pearson) by default, so zero hits give
``p = 0`` with an honest upper bound (about ``3.7 / n`` at 95%), never a
zero-width interval.
"""

from __future__ import annotations

import time
from collections.abc import Sequence

from avrisk.rare.families.base import ExponentialFamily
from avrisk.rare.final_stage import BINOMIAL_INTERVALS, binomial_estimates
from avrisk.rare.problem import (
    FINAL_STAGE,
    BatchFunction,
    RareEventProblem,
    check_positive_int,
    threshold_list,
)
from avrisk.rare.results import Estimate
from avrisk.rare.stages import BatchCache, BatchRecorder, run_stage


def naive_mc(
    f: BatchFunction,
    base: ExponentialFamily,
    gamma: float,
    n: int,
    *,
    seed: int = 0,
    gamma_test: Sequence[float] | float = (),
    batch_size: int | None = None,
    interval: str = "clopper-pearson",
    on_batch: BatchRecorder | None = None,
    cache: BatchCache | None = None,
) -> Estimate:
    """Estimate ``P0(f(X) <= gamma)`` by plain sampling from ``base``.

    Parameters
    ----------
    f : callable
        Batched black box, ``(n, D)`` float64 array to ``(n,)`` values.
    base : ExponentialFamily
        ``P0``.
    gamma : float
        Threshold.
    n : int
        Number of samples (= calls of ``f``).
    seed : int, default=0
        Run seed; the same seed gives the same result whatever ``batch_size``.
    gamma_test : float or sequence of float, default=()
        Further thresholds estimated from the same samples.
    batch_size : int or None, default=None
        Largest number of rows per call of ``f``.
    interval : {"clopper-pearson", "wilson"}, default="clopper-pearson"
        Binomial confidence interval (95%).
    on_batch : callable, optional
        Called with each evaluated :class:`~avrisk.rare.stages.StageBatch`
        (a samples table, a progress bar).
    cache : callable, optional
        ``cache(stage, chunk)`` returns a recorded batch of an interrupted run
        with the same settings, or ``None`` (see :mod:`avrisk.rare.stages`).

    Returns
    -------
    Estimate

    Examples
    --------
    >>> import numpy as np
    >>> from avrisk.rare import FixedCovNormal, naive_mc
    >>> base = FixedCovNormal(np.zeros(1), cov=np.eye(1))
    >>> est = naive_mc(lambda x: x[:, 0], base, gamma=-2.0, n=20_000, seed=1)
    >>> bool(abs(est.p - 0.02275) < 4 * est.stderr)
    True
    """
    start = time.perf_counter()
    n = check_positive_int("n", n)
    if interval not in BINOMIAL_INTERVALS:
        raise ValueError(
            f"interval must be one of {sorted(BINOMIAL_INTERVALS)}; got {interval!r}"
        )
    problem = RareEventProblem(base, f, gamma, threshold_list(gamma_test), batch_size)
    stage = run_stage(
        problem, base, n, seed=seed, stage=FINAL_STAGE, on_batch=on_batch, cache=cache
    )
    return Estimate(
        method="naive_mc",
        gamma=problem.gamma,
        by_gamma=binomial_estimates(stage.values, problem.thresholds, interval),
        n_evals=n,
        wall_time_s=time.perf_counter() - start,
    )
