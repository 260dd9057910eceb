"""Likelihood ratios in log space: weighted means, effective sample sizes.

Importance weights ``w_i = p0(X_i) / q(X_i)`` of rare-event problems routinely
span hundreds of orders of magnitude, so they are handled as ``log w`` and only
exponentiated after subtracting their maximum.
"""

from __future__ import annotations

import numpy as np
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
