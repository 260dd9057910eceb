"""The importance-sampling proposal fitted to subset simulation's particles.

Step 3 of :mod:`avrisk.rare.splitting_importance` (its module docstring says
what the fit does and why): mean shifts of the base's standard normals on the
coordinates the particles say something about, components chosen by the
held-out likelihood of one half of the chains under a fit to the other half,
shrunk by their noise, plus a component for each region the fit leaves out.
The fit knows nothing of how the particles were made: particles of ``P0(. |
f <= gamma)`` in standard-normal space, and the chain of each.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Literal, NamedTuple, Protocol

import numpy as np
from scipy import stats
from scipy.special import logsumexp

from avrisk.rare.chain_moments import block_means, informative_by_moments, moment_errors
from avrisk.rare.families.base import ExponentialFamily, FloatArray
from avrisk.rare.families.standard_space import StandardSpaceShift
from avrisk.rare.mixture_em import (
    MixtureProposal,
    component_log_kernels,
    fit_mixture,
    merge_overlapping,
    seed_components,
)

__all__ = [
    "LIGHT_REGION_SHARE",
    "MIN_REGION_PARTICLES",
    "OUTLIER_TAIL",
    "PREDICTION_FOLDS",
    "THRESHOLDS",
    "HeldOutWeights",
    "ParticleFit",
    "ProposalSettings",
    "held_out_weights",
    "particle_proposal",
    "shrink",
    "slope_direction",
    "with_light_regions",
]

#: Candidate thresholds, in standard errors, beyond which a coordinate's particle
#: mean (or mean square) counts as informative (step 3 of the module
#: docstring), the sparsest first (ties of the held-out score go to it); 0
#: keeps every coordinate.
THRESHOLDS = (4.0, 3.0, 2.5, 2.0, 1.5, 0.0)

#: A particle farther from every fitted shift than a draw of it is with this
#: probability lies in a region of its own (:func:`with_light_regions`).
OUTLIER_TAIL = 1e-6
#: Fewest such particles that make a region of their own.
MIN_REGION_PARTICLES = 3
#: Least proposal weight of a region kept for its separation alone.
LIGHT_REGION_SHARE = 0.02
#: Folds of the chains in :func:`held_out_weights`.
PREDICTION_FOLDS = 10

#: A proposal's fit to particles and their chains: its components, their
#: weights and the coordinates it shifts (inside :func:`particle_proposal`).
Fitter = Callable[
    [FloatArray, np.ndarray],
    tuple[list[ExponentialFamily], FloatArray, np.ndarray],
]


class ProposalSettings(Protocol):
    """The settings the fit reads.

    Those of :class:`~avrisk.rare.splitting_importance.SplittingISSettings`.
    """

    n_components: int
    min_weight: float
    defensive: float
    shift: Literal["all", "searched"]


class HeldOutWeights(NamedTuple):
    """What the particles' held-out weights ``w = p0 / q`` predict of the IS stage.

    The particles follow ``P0(. | f <= gamma)``, so averages over them are
    conditional expectations given the event ``F``. Where ``q <= p0`` (``w
    >= 1``) the proposal is no denser than ``P0``, and in a rare event its
    draws all but never land: importance sampling misses that part of ``p``
    (a bias its own interval does not show, not a variance). Elsewhere its
    draws' ``w 1{F, w < 1}`` have relative variance ``E[w 1{w < 1} | F] / p -
    (1 - s)^2`` per draw (``E_q[(w 1_F)^2] = p E[w | F]``).

    Attributes
    ----------
    uncovered : float
        ``s``, the share of particles with ``w >= 1``: of ``p``, the part the
        importance sample will miss.
    covered_mean_weight : float
        ``E[w 1{w < 1} | F]``, the particles' mean weight where ``w < 1``
        (0 counted elsewhere).
    """

    uncovered: float
    covered_mean_weight: float


class ParticleFit(NamedTuple):
    """The proposal fitted to the particles, and the choices the fit made.

    Attributes
    ----------
    proposal : MixtureProposal
        Mean shifts of the base's standard normals (``StandardSpaceShift``)
        and ``P0`` with weight ``settings.defensive``.
    threshold : float
        The standard errors beyond which a coordinate was shifted (one of
        ``THRESHOLDS``; 0 for a shift along the slope).
    n_shifted : int
        Coordinates shifted.
    along_slope : bool
        Whether the shift is the particles' mean along the direction in which
        ``f`` falls (:func:`slope_direction`) rather than per coordinate.
    held_out : HeldOutWeights
        What the particles' importance weights ``p0 / q`` under fits that did
        not see them predict of the importance-sampling stage, before it is
        drawn (:func:`held_out_weights`).
    """

    proposal: MixtureProposal
    threshold: float
    n_shifted: int
    along_slope: bool = False
    held_out: HeldOutWeights = HeldOutWeights(float("nan"), float("nan"))


def slope_direction(z: FloatArray, values: FloatArray) -> FloatArray | None:
    """The unit direction in which ``f`` falls, by least squares over particles.

    ``f ~ b + w . z`` fitted to the particles with finite values; the direction
    is ``-w / |w|``. For a linear limit state it is exact (whatever the
    particles' correlation, once they span the space); otherwise it is ``f``'s
    average slope over the particles, a candidate the held-out likelihood of
    :func:`particle_proposal` weighs against the per-coordinate fits.

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


def particle_proposal(
    z: FloatArray,
    chain: np.ndarray,
    base: ExponentialFamily,
    settings: ProposalSettings,
    rng: np.random.Generator,
    slope: FloatArray | None = None,
) -> ParticleFit:
    """The importance-sampling proposal fitted to particles (steps 3-4 above).

    Parameters
    ----------
    z : ndarray of shape (n, D)
        Particles of ``P0(. | f <= gamma)`` in the base's standard-normal space.
    chain : ndarray of int, shape (n,)
        The chain of each particle, chains numbered in the order of their
        ancestors (the threshold and the number of components are chosen by
        fitting one half of the chains and scoring the other).
    base : ExponentialFamily
        ``P0``.
    settings : ProposalSettings
        ``n_components``, ``min_weight``, ``defensive`` and ``shift``.
    rng : numpy.random.Generator
        For the k-means++ seeding.
    slope : ndarray of shape (D,), optional
        A unit direction in which ``f`` falls (:func:`slope_direction`): one
        more candidate, a single shift along it by the particles' mean, shrunk
        by its noise. It wins where many coordinates each matter a little and
        the per-coordinate mean is mostly noise (``D / n_eff`` in squared norm
        against ``1 / n_eff`` along one direction).

    Returns
    -------
    ParticleFit

    Examples
    --------
    >>> from avrisk.rare import FixedCovNormal
    >>> from avrisk.rare.splitting_importance import SplittingISSettings
    >>> base = FixedCovNormal(np.zeros(2), cov=np.eye(2))
    >>> rng = np.random.default_rng(0)
    >>> z = np.vstack([rng.normal((4, 0), 0.3, (500, 2)),
    ...                rng.normal((-4, 0), 0.3, (500, 2))])
    >>> chain = rng.permutation(1000) // 10
    >>> fit = particle_proposal(z, chain, base, SplittingISSettings(), rng)
    >>> sorted(round(float(c.mean[0])) for c in fit.proposal.components)
    [-4, 4]
    """
    allowed = (
        np.ones(base.dim, dtype=bool)
        if settings.shift == "all"
        else np.asarray(base.searched_coordinates(), dtype=bool)
    )

    along = None
    if slope is not None and np.any(allowed & (slope != 0)):
        along = np.where(allowed, slope, 0.0)
        along = along / np.linalg.norm(along)

    def fit_along(
        points: FloatArray, point_chain: np.ndarray
    ) -> tuple[list[ExponentialFamily], FloatArray, np.ndarray]:
        """One shift along ``along``: the particles' mean there, shrunk."""
        shifted = along != 0
        mean, stderr = block_means(points @ along[:, None], point_chain)
        shift = StandardSpaceShift(base, mean[0] * along, searched=shifted)
        noise = float(np.nan_to_num(stderr[0] ** 2))
        return [shrink(shift, 1.0, noise)], np.ones(1), shifted

    def fit(
        points: FloatArray, point_chain: np.ndarray, threshold: float, k: int
    ) -> tuple[list[ExponentialFamily], FloatArray, np.ndarray]:
        """Shifts of the informative coordinates, ``k`` components, shrunk."""
        moments = moment_errors(points, point_chain)
        shifted = allowed & informative_by_moments(moments, threshold)
        structure = StandardSpaceShift(base, searched=shifted)
        masked = np.where(shifted, points, 0.0)  # the others play no part in it
        weights = np.full(len(points), 1.0 / len(points))
        start = seed_components(structure, masked, weights, k, rng)
        mixture = fit_mixture(*start, masked, weights, settings.min_weight)
        components, shares = merge_overlapping(mixture.components, mixture.weights)
        noise = float(np.nansum(moments[0][1][shifted] ** 2))
        shrunk = [
            shrink(c, share, noise) for c, share in zip(components, shares, strict=True)
        ]
        return shrunk, shares, shifted

    first = chain < (chain.max() + 1) / 2

    def held_out_points(fitter: Fitter) -> FloatArray:
        """Each particle's log-likelihood under the fit to the other half, (n,)."""
        return cross_fitted_log_ratios(
            z, chain, (~first, first), lambda p, c: fitter(p, c)[:2]
        )

    def summed(scores: FloatArray) -> float:
        """Mean held-out log-likelihood of each half, summed over the halves."""
        return float(scores[~first].mean() + scores[first].mean())

    def clearly_better(a: FloatArray, b: FloatArray) -> bool:
        """Whether held-out scores ``a`` beat ``b`` by two standard errors.

        The paired differences' mean over particles, its standard error from
        blocks of chains (:func:`block_means`, the chains' correlation in it).
        """
        mean, stderr = block_means((a - b)[:, None], chain)
        return bool(mean[0] > 2.0 * np.nan_to_num(stderr[0], nan=np.inf))

    def per_coordinate(threshold: float, k: int) -> Fitter:
        """:func:`fit` with its threshold and number of components set."""
        return lambda points, point_chain: fit(points, point_chain, threshold, k)

    threshold = THRESHOLDS[0]
    chosen = per_coordinate(threshold, 1)
    along_slope = False
    if first.any() and not first.all():  # max keeps the first of ties
        threshold = max(
            THRESHOLDS, key=lambda t: summed(held_out_points(per_coordinate(t, 1)))
        )
        points = {
            k: held_out_points(per_coordinate(threshold, k))
            for k in range(1, settings.n_components + 1)
        }
        k = max(points, key=lambda k: summed(points[k]))
        chosen = per_coordinate(threshold, k)
        # the shift along the slope, if clearly better than the best
        # per-coordinate mixture (a close call goes to the mixture)
        if along is not None and clearly_better(held_out_points(fit_along), points[k]):
            chosen, threshold, along_slope = fit_along, 0.0, True
    components, weights, shifted = chosen(z, chain)
    components, weights = with_light_regions(z, components, weights, shifted, base, rng)
    proposal = MixtureProposal(components, weights, base, settings.defensive)
    return ParticleFit(
        proposal,
        threshold,
        int(np.count_nonzero(shifted)),
        along_slope=along_slope,
        held_out=held_out_weights(z, chain, chosen, base, settings.defensive, rng),
    )


def cross_fitted_log_ratios(
    z: FloatArray,
    chain: np.ndarray,
    held_out: Sequence[np.ndarray],
    fit: Callable[
        [FloatArray, np.ndarray], tuple[Sequence[ExponentialFamily], FloatArray]
    ],
) -> FloatArray:
    """``log(sum_k pi_k q_k / p0)`` of each particle, (n,), by a fit not seeing it.

    Parameters
    ----------
    z : ndarray of shape (n, D)
        The particles in standard-normal space.
    chain : ndarray of int, shape (n,)
        Each particle's chain.
    held_out : sequence of ndarray of bool, shape (n,)
        Disjoint masks covering every particle, fitted in this order: each
        part is scored under ``fit`` of the particles outside it.
    fit : callable
        ``fit(points, point_chain) -> (components, weights)``, shifts of one
        structure and their weights ``pi_k``.
    """
    log_ratios = np.empty(len(z))
    for test in held_out:
        components, weights = fit(z[~test], chain[~test])
        log_joint = np.log(weights) + component_log_kernels(components, z[test])
        log_ratios[test] = logsumexp(log_joint, axis=1)
    return log_ratios


def held_out_weights(
    z: FloatArray,
    chain: np.ndarray,
    fitter: Fitter,
    base: ExponentialFamily,
    defensive: float,
    rng: np.random.Generator,
) -> HeldOutWeights:
    """The particles' weights ``p0 / q`` under fits that did not see them.

    The chains are dealt into ``PREDICTION_FOLDS`` folds; each fold's
    particles are weighed under the proposal fitted (by ``fitter``, the
    chosen fit, with the light regions of all the particles as the final
    proposal has them) to the other folds. Each fit sees 90% of the chains,
    so it is nearly the final fit's equal even in hundreds of dimensions (a
    fit to half of them overstated the final sample's variance there). The
    particles follow ``P0(. | f <= gamma)``, so their weights say, region by
    region, how the importance sample will fare (:class:`HeldOutWeights`).

    Parameters
    ----------
    z : ndarray of shape (n, D)
        The particles in standard-normal space.
    chain : ndarray of int, shape (n,)
        Each particle's chain.
    fitter : callable
        ``fitter(points, point_chain) -> (components, weights, shifted)``.
    base : ExponentialFamily
    defensive : float
        The proposal's share of ``P0``, in [0, 1).
    rng : numpy.random.Generator
        For the fits' seeding.

    Returns
    -------
    HeldOutWeights
        NaN in both fields with fewer than ``PREDICTION_FOLDS`` chains.
    """
    chains = np.unique(chain)
    if len(chains) < PREDICTION_FOLDS:
        return HeldOutWeights(float("nan"), float("nan"))
    fold = np.searchsorted(chains, chain) % PREDICTION_FOLDS
    log_ratios = cross_fitted_log_ratios(  # log(sum_k pi_k q_k / p0), (n,)
        z,
        chain,
        [fold == k for k in range(PREDICTION_FOLDS)],
        lambda p, c: with_light_regions(z, *fitter(p, c), base, rng),
    )
    if defensive > 0:
        log_ratios = np.logaddexp(
            math.log(defensive), math.log1p(-defensive) + log_ratios
        )
    w = np.exp(-log_ratios)
    covered = w < 1.0
    return HeldOutWeights(
        uncovered=float(np.mean(~covered)),
        covered_mean_weight=float(np.mean(np.where(covered, w, 0.0))),
    )


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
    scale = max(0.0, 1.0 - noise / (share * size))
    return component.with_natural_params(scale * component.mean)
