"""Means and their standard errors over MCMC chains of particles.

Subset simulation's particles come in chains, correlated within a chain and
independent between chains (their ancestors are independent draws). A mean
over the particles has a standard error that the chains, not the particles,
set; :func:`block_means` takes it from the spread of the means of blocks of
consecutive chains. :func:`informative_coordinates` uses it to ask which
coordinates of standard-normal particles are off ``N(0, 1)``: the ones a
proposal fitted to them should move (:mod:`avrisk.rare.particle_fit`).

Chains are not the only correlation. After a few levels the chains of a set
can descend from a handful of the first set's draws, and every descendant
keeps some of its ancestor's coordinates where ``f`` does not pull them (a
pCN step forgets about ``beta^2 / 2`` of a coordinate). Blocks of chains that
share ancestors then agree about a coordinate that says nothing of the
event, and its mean passes for informative. What the blocks miss is common to
every coordinate (the same family tree), so its size can be read off the
coordinates themselves, most of which an event leaves at ``N(0, 1)``: the
spread of their ``mean / stderr`` (:func:`empirical_null_scale`; Efron's
empirical null, read off the lower quartile so that up to three in four
coordinates may be informative). :func:`uninformed_coordinates` widens the
standard errors by it to name the coordinates no fit should trust, which
:func:`~avrisk.rare.splitting_moves.refreshed` draws afresh.

References
----------
B. Efron. "Large-scale simultaneous hypothesis testing: the choice of a null
hypothesis." Journal of the American Statistical Association 99, 2004.
"""

from __future__ import annotations

import numpy as np

from avrisk.rare.families.base import FloatArray

__all__ = [
    "N_BLOCKS",
    "block_means",
    "empirical_null_scale",
    "informative_by_moments",
    "informative_coordinates",
    "moment_errors",
    "uninformed_coordinates",
]

#: Blocks of chains whose means give the standard errors.
N_BLOCKS = 20
#: Quantile of ``|mean / stderr|`` over the coordinates that sets the empirical
#: null (:func:`empirical_null_scale`).
NULL_QUANTILE = 0.25
#: That quantile of ``|t|`` for ``t ~ N(0, 1)`` (``scipy.stats.halfnorm.ppf``).
NULL_QUANTILE_VALUE = 0.3186


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


def empirical_null_scale(mean: FloatArray, stderr: FloatArray) -> float:
    """How many times wider than ``N(0, 1)`` the coordinates' ``mean / stderr`` spread.

    The lower quartile of ``|mean / stderr|`` over the coordinates, over its
    value 0.3186 under ``N(0, 1)``, and at least 1 (module docstring); 1
    where a standard error is NaN or 0, or with fewer than 4 coordinates (a
    quartile of fewer says nothing of the null).

    Examples
    --------
    >>> t = np.array([0.6, -0.9, 1.2, 40.0, 30.0])
    >>> round(empirical_null_scale(t, np.ones(5)), 2)
    2.82
    >>> empirical_null_scale(np.array([0.01, -0.02, 0.03, 0.01]), np.full(4, 0.1))
    1.0
    >>> empirical_null_scale(np.array([30.0, 40.0]), np.ones(2))  # too few
    1.0
    """
    few = len(mean) * NULL_QUANTILE < 1
    if few or not (np.isfinite(stderr).all() and (stderr > 0).all()):
        return 1.0
    spread = float(np.quantile(np.abs(mean / stderr), NULL_QUANTILE))
    return max(1.0, spread / NULL_QUANTILE_VALUE)


def uninformed_coordinates(
    z: FloatArray, chain: np.ndarray, threshold: float
) -> np.ndarray:
    """Coordinates whose particle mean and mean square stay near ``N(0, 1)``'s.

    Those :func:`informative_by_moments` does not name at ``threshold``, each
    moment's errors widened by :func:`empirical_null_scale`: the coordinates
    the particles do not show the event to depend on, once what their
    ancestors share is allowed for (module docstring).

    Parameters
    ----------
    z : ndarray of shape (n, D)
        Particles in standard-normal space.
    chain : ndarray of int, shape (n,)
        Their chains, numbered in the order of their ancestors.
    threshold : float
        Widened standard errors.

    Returns
    -------
    ndarray of bool, shape (D,)
        None with fewer than 4 chains (no standard errors).

    Examples
    --------
    Two ancestors, each of which left its own offsets in the coordinates the
    event does not touch (1 to 9); coordinate 0 holds the event:

    >>> rng = np.random.default_rng(2)
    >>> offsets = np.repeat(rng.normal(0.0, 0.7, (2, 10)), 500, axis=0)
    >>> z = rng.standard_normal((1000, 10)) * 0.6 + offsets
    >>> z[:, 0] = 3.0 + 0.3 * rng.standard_normal(1000)
    >>> chain = np.arange(1000) // 10
    >>> np.flatnonzero(informative_coordinates(z, chain, 4.0)).tolist()
    [0, 1, 2, 3, 4, 6, 7, 8, 9]
    >>> np.flatnonzero(~uninformed_coordinates(z, chain, 4.0)).tolist()
    [0]
    """
    widened = [
        (mean, stderr * empirical_null_scale(mean, stderr))
        for mean, stderr in moment_errors(z, chain)
    ]
    return ~informative_by_moments(widened, threshold)
