"""Means and their standard errors over MCMC chains of particles.

Subset simulation's particles come in chains, correlated within a chain and
independent between chains (their ancestors are independent draws). A mean
over the particles has a standard error that the chains, not the particles,
set; :func:`block_means` takes it from the spread of the means of blocks of
consecutive chains. :func:`informative_coordinates` uses it to ask which
coordinates of standard-normal particles are off ``N(0, 1)``: the ones a
proposal fitted to them should move (:mod:`avrisk.rare.particle_fit`).
"""

from __future__ import annotations

import numpy as np

from avrisk.rare.families.base import FloatArray

__all__ = [
    "N_BLOCKS",
    "block_means",
    "informative_by_moments",
    "informative_coordinates",
    "moment_errors",
]

#: Blocks of chains whose means give the standard errors.
N_BLOCKS = 20


def block_means(z: FloatArray, chain: np.ndarray) -> tuple[FloatArray, FloatArray]:
    """Mean of each coordinate and its standard error, from blocks of chains.

    Parameters
    ----------
    z : ndarray of shape (n, D)
        Particles (or any per-particle quantity).
    chain : ndarray of int, shape (n,)
        Their chains, numbered in the order of their ancestors (any integers
        in that order).

    Returns
    -------
    mean, stderr : ndarray of shape (D,)
        ``stderr`` from the spread of the means of ``N_BLOCKS`` blocks of
        consecutive chains (fewer blocks with fewer chains); NaN with fewer
        than 4 chains (then nothing is shrunk).
    """
    _, order = np.unique(chain, return_inverse=True)
    n_chains = int(order.max()) + 1
    if n_chains < 4:
        return z.mean(axis=0), np.full(z.shape[1], np.nan)
    blocks = min(N_BLOCKS, n_chains)
    block = order * blocks // n_chains
    means = np.stack([z[block == b].mean(axis=0) for b in range(blocks)])
    return z.mean(axis=0), means.std(axis=0, ddof=1) / np.sqrt(blocks)


def moment_errors(
    z: FloatArray, chain: np.ndarray
) -> tuple[tuple[FloatArray, FloatArray], tuple[FloatArray, FloatArray]]:
    """:func:`block_means` of the particles ``z`` and of ``z^2 - 1``, in that order.

    Under ``N(0, 1)`` both moments are 0: what :func:`informative_coordinates`
    tests, and the first one's standard errors are the noise of a fitted
    shift (:func:`avrisk.rare.particle_shifts.shrink`).
    """
    return block_means(z, chain), block_means(z * z - 1.0, chain)


def informative_by_moments(
    moments: tuple[tuple[FloatArray, FloatArray], ...], threshold: float
) -> np.ndarray:
    """Coordinates where a moment is off 0 by more than ``threshold`` errors.

    Parameters
    ----------
    moments : tuple of (mean, stderr) pairs, each of shape (D,)
        As :func:`moment_errors` gives them.
    threshold : float
        Standard errors; 0 keeps every coordinate, as do standard errors
        that are all NaN (fewer than 4 chains).

    Returns
    -------
    ndarray of bool, shape (D,)
    """
    few_chains = np.isnan(moments[0][1]).all()  # no standard errors: keep all
    informative = np.full(moments[0][0].shape, threshold == 0.0 or few_chains)
    for mean, stderr in moments:
        informative |= np.abs(mean) > threshold * stderr
    return informative


def informative_coordinates(
    z: FloatArray, chain: np.ndarray, threshold: float
) -> np.ndarray:
    """Coordinates whose particle mean or mean square is off ``N(0, 1)``'s.

    Parameters
    ----------
    z : ndarray of shape (n, D)
        Particles in standard-normal space.
    chain : ndarray of int, shape (n,)
        Their chains, numbered in the order of their ancestors (any integers
        in that order).
    threshold : float
        Standard errors.

    Returns
    -------
    ndarray of bool, shape (D,)
        True where ``|mean(z_i)|`` or ``|mean(z_i^2) - 1|`` exceeds
        ``threshold`` standard errors (:func:`block_means`); every
        coordinate with fewer than 4 chains or ``threshold`` 0.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> z = rng.standard_normal((2000, 4)) * [1.0, 1.0, 3.0, 1.0] + [0.0, 2.0, 0.0, 0.0]
    >>> informative_coordinates(z, np.arange(2000) // 10, 3.0).tolist()
    [False, True, True, False]
    """
    return informative_by_moments(moment_errors(z, chain), threshold)
