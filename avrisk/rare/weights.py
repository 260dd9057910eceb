"""Likelihood ratios in log space: weighted means, effective sample sizes.

Importance weights ``w_i = p0(X_i) / q(X_i)`` of rare-event problems routinely
span hundreds of orders of magnitude, so they are handled as ``log w`` and only
exponentiated after subtracting their maximum.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import stats
from scipy.special import logsumexp, softmax

from avrisk.rare.families.base import FloatArray


def normalized_weights(log_w: FloatArray) -> FloatArray:
    """Self-normalised weights ``w_i / sum_j w_j``, shape (n,), summing to one."""
    return softmax(np.asarray(log_w, dtype=np.float64))


def kish_ess(log_w: FloatArray) -> float:
    """Kish effective sample size ``(sum w)^2 / sum w^2`` (0 for no weights)."""
    log_w = np.asarray(log_w, dtype=np.float64)
    if log_w.size == 0 or not np.isfinite(log_w).any():
        return 0.0
    return float(np.exp(2.0 * logsumexp(log_w) - logsumexp(2.0 * log_w)))


def weighted_mean_and_stderr(
    log_w: FloatArray, hits: np.ndarray
) -> tuple[float, float]:
    """Mean and standard error of ``w_i 1{hit_i}`` over all ``n`` samples.

    This is the unbiased importance-sampling estimate ``p_hat = (1/n) sum w_i
    h_i`` and its standard error ``std(w h, ddof=1) / sqrt(n)``, computed after
    scaling by the largest hit weight so that no weight over- or underflows.

    Parameters
    ----------
    log_w : ndarray of shape (n,)
        Log-likelihood ratios ``log p0 - log q``.
    hits : ndarray of bool, shape (n,)
        Event indicators.

    Returns
    -------
    p_hat, stderr : float
    """
    log_w = np.asarray(log_w, dtype=np.float64)
    n = log_w.size
    shift = float(log_w[hits].max()) if hits.any() else -np.inf
    if shift == -np.inf:  # no hit, or hits that the base gives no mass
        return 0.0, 0.0
    terms = np.where(hits, np.exp(np.where(hits, log_w, shift) - shift), 0.0)
    scale = np.exp(shift)
    mean = scale * terms.mean()
    std = scale * terms.std(ddof=1) if n > 1 else np.inf
    return float(mean), float(std / np.sqrt(n))


#: Above this Pareto tail index the weights' variance is effectively infinite
#: for the sample at hand and the standard error cannot be trusted (Vehtari et
#: al., "Pareto smoothed importance sampling", JMLR 25, 2024).
MAX_RELIABLE_PARETO_K = 0.7

#: Fewest tail weights the Pareto fit is made on.
MIN_PARETO_TAIL = 5


def pareto_tail_index(log_w: FloatArray) -> float:
    """Shape ``k`` of a generalised Pareto fitted to the largest weights.

    The PSIS diagnostic (Vehtari et al. 2024): the largest ``M = min(n / 5, 3
    sqrt(n))`` weights, less the next one, are fitted by maximum likelihood
    (:func:`scipy.stats.genpareto.fit`, location 0). A weight distribution
    with tail ``P(w > t) ~ t^(-1/k)`` has a finite variance only for ``k <
    1/2``; for ``k > 0.7`` the importance-sampling estimate converges too
    slowly for its standard error to mean much at any practical ``n``. The
    fit is scale-free, so ``log_w`` may be shifted by any constant.

    Parameters
    ----------
    log_w : ndarray of shape (n,)
        Log-weights of the terms of the estimate (for ``P(f <= gamma)``, those
        of the hits).

    Returns
    -------
    float
        ``k``; NaN with fewer than ``MIN_PARETO_TAIL`` tail weights; ``-inf``
        when the largest weights are all equal (no tail at all).

    Examples
    --------
    >>> import numpy as np
    >>> from scipy import stats
    >>> w = stats.genpareto.rvs(0.8, size=20_000, random_state=0)
    >>> k = pareto_tail_index(np.log(w))  # about 0.8, standard error about 0.09
    >>> bool(0.6 < k < 1.0)
    True
    """
    log_w = np.sort(np.asarray(log_w, dtype=np.float64))
    log_w = log_w[np.isfinite(log_w)]
    n = log_w.size
    m = int(min(0.2 * n, 3.0 * math.sqrt(n)))
    if m < MIN_PARETO_TAIL:
        return math.nan
    w = np.exp(log_w[-(m + 1) :] - log_w[-1])
    excess = w[1:] - w[0]
    if excess.max() <= 0.0:
        return -math.inf
    k, _, _ = stats.genpareto.fit(excess / excess.max(), floc=0.0)
    return float(k)
