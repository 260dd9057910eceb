"""Mean shifts of the base's standard normals fitted to particles.

The pieces of the proposal :mod:`avrisk.rare.particle_fit` fits to subset
simulation's particles: shifts of the coordinates the particles say something
about, ``k`` components (:func:`fit_per_coordinate`), or one shift along the
direction in which ``f`` falls (:func:`slope_direction`,
:func:`fit_along_direction`), each shrunk by its noise (:func:`shrink`), plus
a component for each region the fit leaves out (:func:`with_light_regions`);
and the variance of each shifted coordinate, fitted around the shifts
(:func:`with_fitted_variances`).
Which of them the proposal uses is :mod:`avrisk.rare.particle_fit`'s choice.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy import stats
from scipy.special import logsumexp

from avrisk.rare.chain_moments import block_means, informative_by_moments, moment_errors
from avrisk.rare.families.base import ExponentialFamily, FloatArray
from avrisk.rare.families.standard_space import StandardSpaceShift
from avrisk.rare.families.standard_space_normal import (
    VARIANCE_RANGE,
    StandardSpaceNormal,
)
from avrisk.rare.mixture_em import (
    component_log_kernels,
    fit_mixture,
    merge_overlapping,
    seed_components,
)

__all__ = [
    "LIGHT_REGION_SHARE",
    "MIN_REGION_PARTICLES",
    "OUTLIER_TAIL",
    "fit_along_direction",
    "fit_per_coordinate",
    "log_ratios_to_base",
    "shrink",
    "shrinkage",
    "with_fitted_variances",
    "slope_direction",
    "with_light_regions",
]

#: A particle farther from every fitted shift than a draw of it is with this
#: probability lies in a region of its own (:func:`with_light_regions`).
OUTLIER_TAIL = 1e-6
#: Fewest such particles that make a region of their own.
MIN_REGION_PARTICLES = 3
#: Least proposal weight of a region kept for its separation alone.
LIGHT_REGION_SHARE = 0.02


def slope_direction(z: FloatArray, values: FloatArray) -> FloatArray | None:
    """The unit direction in which ``f`` falls, by least squares over particles.

    ``f ~ b + w . z`` fitted to the particles with finite values; the direction
    is ``-w / |w|``. For a linear limit state it is exact (whatever the
    particles' correlation, once they span the space); otherwise it is ``f``'s
    average slope over the particles, a candidate the held-out likelihood of
    :func:`~avrisk.rare.particle_fit.particle_proposal` weighs against the
    per-coordinate fits.

    Parameters
    ----------
    z : ndarray of shape (n, D)
        Particles in standard-normal space (e.g. the last level's).
    values : ndarray of shape (n,)
        Their ``f``.

    Returns
    -------
    ndarray of shape (D,) or None
        None with fewer than ``D + 2`` finite values or ``f`` constant on them.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> z = rng.standard_normal((50, 3))
    >>> (slope_direction(z, 5.0 - 2.0 * z[:, 0]).round(6) + 0.0).tolist()
    [1.0, 0.0, 0.0]
    """
    finite = np.isfinite(values)
    if np.count_nonzero(finite) < z.shape[1] + 2:
        return None
    points, f = z[finite], values[finite]
    f = f - f.mean()
    if not f.any():
        return None
    w, *_ = np.linalg.lstsq(points - points.mean(axis=0), f, rcond=None)
    norm = float(np.linalg.norm(w))
    return None if norm == 0.0 or not np.isfinite(norm) else -w / norm


def fit_per_coordinate(
    points: FloatArray,
    point_chain: np.ndarray,
    *,
    base: ExponentialFamily,
    allowed: np.ndarray,
    threshold: float,
    k: int,
    min_weight: float,
    rng: np.random.Generator,
) -> tuple[list[ExponentialFamily], FloatArray, np.ndarray]:
    """Shifts of the informative coordinates, ``k`` components, shrunk.

    Parameters
    ----------
    points : ndarray of shape (n, D)
        Particles in the base's standard-normal space.
    point_chain : ndarray of int, shape (n,)
        The chain of each (the coordinates' standard errors come from blocks
        of chains, :func:`~avrisk.rare.chain_moments.moment_errors`).
    base : ExponentialFamily
        ``P0``.
    allowed : ndarray of bool, shape (D,)
        The coordinates a shift may move.
    threshold : float
        Standard errors beyond which a coordinate's mean, or mean square,
        counts as informative.
    k : int
        Components seeded (k-means++), fitted by EM and merged.
    min_weight : float
        Share of the points below which a component dies in EM.
    rng : numpy.random.Generator
        For the seeding.

    Returns
    -------
    components : list of StandardSpaceShift
    weights : ndarray of shape (K,)
    shifted : ndarray of bool, shape (D,)
        The coordinates the shifts move.
    """
    moments = moment_errors(points, point_chain)
    shifted = allowed & informative_by_moments(moments, threshold)
    structure = StandardSpaceShift(base, searched=shifted)
    masked = np.where(shifted, points, 0.0)  # the others play no part in it
    weights = np.full(len(points), 1.0 / len(points))
    start = seed_components(structure, masked, weights, k, rng)
    mixture = fit_mixture(*start, masked, weights, min_weight)
    components, shares = merge_overlapping(mixture.components, mixture.weights)
    noise = float(np.nansum(moments[0][1][shifted] ** 2))
    shrunk = [
        shrink(c, share, noise) for c, share in zip(components, shares, strict=True)
    ]
    return shrunk, shares, shifted


def fit_along_direction(
    points: FloatArray,
    point_chain: np.ndarray,
    *,
    base: ExponentialFamily,
    along: FloatArray,
) -> tuple[list[ExponentialFamily], FloatArray, np.ndarray]:
    """One shift along ``along``: the particles' mean there, shrunk.

    Parameters
    ----------
    points : ndarray of shape (n, D)
        Particles in the base's standard-normal space.
    point_chain : ndarray of int, shape (n,)
        The chain of each (the mean's standard error from blocks of chains).
    base : ExponentialFamily
        ``P0``.
    along : ndarray of shape (D,)
        A unit direction; its nonzero coordinates are the ones shifted.

    Returns
    -------
    components : list of one StandardSpaceShift
    weights : ndarray of shape (1,)
    shifted : ndarray of bool, shape (D,)
    """
    shifted = along != 0
    mean, stderr = block_means(points @ along[:, None], point_chain)
    shift = StandardSpaceShift(base, mean[0] * along, searched=shifted)
    noise = float(np.nan_to_num(stderr[0] ** 2))
    return [shrink(shift, 1.0, noise)], np.ones(1), shifted


def with_light_regions(
    z: FloatArray,
    components: Sequence[ExponentialFamily],
    weights: FloatArray,
    shifted: np.ndarray,
    base: ExponentialFamily,
    rng: np.random.Generator,
) -> tuple[list[ExponentialFamily], FloatArray]:
    """The fit, plus a component for each region its components leave out.

    A particle farther from every fitted shift than a draw of it would be
    with probability ``OUTLIER_TAIL`` (its squared distance over the shifted
    coordinates against ``chi^2`` of as many degrees of freedom) lies in a
    region of its own: a region few chains reached, which the held-out halves
    cannot vouch for (one half holds it, the other not) and EM drops under
    ``min_weight``. With at least ``MIN_REGION_PARTICLES`` such particles,
    shifts are fitted to them alone (k-means++ seeding, EM, merging) and kept
    unshrunk, each with a weight of its particles' share but at least
    ``LIGHT_REGION_SHARE``: their share of the particles is that of ``p``
    only on average, and a region a search barely reached may hold more.

    Parameters
    ----------
    z : ndarray of shape (n, D)
        The particles in standard-normal space.
    components : sequence of StandardSpaceShift
        The fitted shifts; ``weights`` their weights, shape (K,).
    shifted : ndarray of bool, shape (D,)
        The coordinates the shifts move.
    base : ExponentialFamily
    rng : numpy.random.Generator

    Returns
    -------
    components : list of ExponentialFamily
    weights : ndarray of shape (K',), summing to 1
    """
    d = int(np.count_nonzero(shifted))
    if d == 0:
        return list(components), weights
    masked = np.where(shifted, z, 0.0)
    means = np.array([c.mean for c in components])
    far = ((masked[:, None, :] - means[None]) ** 2).sum(axis=2).min(axis=1)
    outside = far > stats.chi2.isf(OUTLIER_TAIL, d)
    n_out = int(np.count_nonzero(outside))
    if n_out < MIN_REGION_PARTICLES:
        return list(components), weights
    structure = StandardSpaceShift(base, searched=shifted)
    points = masked[outside]
    even = np.full(n_out, 1.0 / n_out)
    k = max(1, n_out // MIN_REGION_PARTICLES)
    start = seed_components(structure, points, even, k, rng)
    fit = fit_mixture(*start, points, even, 1.0 / n_out)
    light, shares = merge_overlapping(fit.components, fit.weights)
    light_weights = np.maximum(shares * n_out / len(z), LIGHT_REGION_SHARE)
    kept = np.asarray(weights) * (1.0 - light_weights.sum())
    return [*components, *light], np.concatenate([kept, light_weights])


def shrink(
    component: StandardSpaceShift, share: float, noise: float
) -> StandardSpaceShift:
    """A fitted shift ``m`` scaled by ``c = max(0, 1 - noise / (share |m|^2))``.

    Parameters
    ----------
    component : StandardSpaceShift
        The fit, of ``share`` of the particles.
    share : float
        Its mixture weight, in (0, 1].
    noise : float
        Sum of the shifted coordinates' squared standard errors of the mean
        of all particles (a component of a share ``pi`` has ``1 / pi`` times
        that noise).

    Examples
    --------
    >>> from avrisk.rare import FixedCovNormal
    >>> base = FixedCovNormal(np.zeros(2), cov=np.eye(2))
    >>> fit = StandardSpaceShift(base, [3.0, 4.0])
    >>> shrink(fit, 0.5, 2.5).mean.round(6).tolist()  # c = 1 - 2.5 / (0.5 * 25)
    [2.4, 3.2]
    """
    size = float(component.mean @ component.mean)
    if size == 0.0:
        return component
    return component.with_natural_params(
        shrinkage(noise, share * size) * component.mean
    )


def shrinkage(noise: float, size: float) -> float:
    """James-Stein's ``c = max(0, 1 - noise / size)`` of a fit of squared norm ``size``.

    ``size`` overstates the true squared norm by about ``noise``; ``c`` is the
    scale of the fit that minimises the expected squared distance to the truth.
    """
    return max(0.0, 1.0 - noise / size)


def with_fitted_variances(
    points: FloatArray,
    point_chain: np.ndarray,
    components: Sequence[StandardSpaceShift],
    weights: FloatArray,
    shifted: np.ndarray,
) -> tuple[list[StandardSpaceNormal], FloatArray, np.ndarray]:
    """The fitted shifts, each with the variance of its particles around it.

    Each particle is shared among the shifts by its responsibilities under
    them; a component's variance of coordinate ``i`` is its share's mean of
    ``(z_i - mu_i)^2`` on the shifted coordinates (1 elsewhere). The log
    variances are shrunk towards 0 as :func:`shrink` shrinks a shift, by
    their noise: ``(se / v)^2`` summed over the coordinates, ``se`` from
    blocks of chains (:func:`~avrisk.rare.chain_moments.block_means`).

    Parameters
    ----------
    points : ndarray of shape (n, D)
        Particles in the base's standard-normal space.
    point_chain : ndarray of int, shape (n,)
        The chain of each.
    components : sequence of StandardSpaceShift
        The fitted (shrunk) shifts; ``weights`` their weights, shape (K,).
    shifted : ndarray of bool, shape (D,)
        The coordinates the shifts move.

    Returns
    -------
    components : list of StandardSpaceNormal
    weights : ndarray of shape (K,)
        As given.
    shifted : ndarray of bool, shape (D,)
        As given.
    """
    masked = np.where(shifted, points, 0.0)
    log_joint = np.log(weights) + component_log_kernels(components, masked)
    responsibility = np.exp(log_joint - logsumexp(log_joint, axis=1, keepdims=True))
    scaled = []
    for k, component in enumerate(components):
        share = responsibility[:, k] / responsibility[:, k].mean()
        squares = share[:, None] * (masked - component.mean) ** 2
        variance, stderr = block_means(squares[:, shifted], point_chain)
        variance = np.clip(variance, *VARIANCE_RANGE)
        log_variance = np.log(variance)
        noise = float(np.nansum((stderr / variance) ** 2))
        size = float(log_variance @ log_variance)
        scale = shrinkage(noise, size) if size > 0 else 0.0
        full = np.ones(len(shifted))
        full[shifted] = np.exp(scale * log_variance)
        scaled.append(StandardSpaceNormal.of_shift(component, full))
    return scaled, weights, shifted


def log_ratios_to_base(
    components: Sequence[ExponentialFamily], z: FloatArray
) -> FloatArray:
    """``log(q_k / p0)`` of each standard-space component at ``z``, shape (n, K).

    Parameters
    ----------
    components : sequence of StandardSpaceShift or StandardSpaceNormal
    z : ndarray of shape (n, D)
        Points in the base's standard-normal space.
    """
    if all(isinstance(c, StandardSpaceShift) for c in components):
        return component_log_kernels(components, z)  # their carrier is p0
    return np.stack([as_normal(c).log_ratio(z) for c in components], axis=1)


def as_normal(component: ExponentialFamily) -> StandardSpaceNormal:
    """A standard-space component as a :class:`StandardSpaceNormal`."""
    if isinstance(component, StandardSpaceShift):
        return StandardSpaceNormal.of_shift(component)
    if not isinstance(component, StandardSpaceNormal):
        raise TypeError(f"not a standard-space component: {type(component).__name__}")
    return component
