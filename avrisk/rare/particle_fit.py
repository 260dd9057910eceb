"""The importance-sampling proposal fitted to subset simulation's particles.

Step 3 of :mod:`avrisk.rare.splitting_importance` (its module docstring says
what the fit does and why): mean shifts of the base's standard normals on the
coordinates the particles say something about, with their variances where
that clearly fits better, components chosen by the
held-out likelihood of one half of the chains under a fit to the other half,
shrunk by their noise, plus a component for each region the fit leaves out.
The shifts themselves are fitted in :mod:`avrisk.rare.particle_shifts`; this
module chooses among them and predicts, from the particles, how the
importance sample will fare. The fit knows nothing of how the particles were
made: particles of ``P0(. | f <= gamma)`` in standard-normal space, and the
chain of each.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from typing import Literal, NamedTuple, Protocol

import numpy as np
from scipy.special import logsumexp

from avrisk.rare.chain_moments import block_means
from avrisk.rare.families.base import ExponentialFamily, FloatArray
from avrisk.rare.mixture_em import MixtureProposal
from avrisk.rare.particle_shifts import (
    as_normal,
    fit_along_direction,
    fit_per_coordinate,
    log_ratios_to_base,
    with_fitted_variances,
    with_light_regions,
)

__all__ = [
    "PREDICTION_FOLDS",
    "THRESHOLDS",
    "ChainHalves",
    "FitChoice",
    "HeldOutWeights",
    "ParticleFit",
    "ProposalSettings",
    "choose_fit",
    "held_out_weights",
    "particle_proposal",
]

#: Candidate thresholds, in standard errors, beyond which a coordinate's particle
#: mean (or mean square) counts as informative (step 3 of the module
#: docstring), the sparsest first (ties of the held-out score go to it); 0
#: keeps every coordinate.
THRESHOLDS = (4.0, 3.0, 2.5, 2.0, 1.5, 0.0)

#: Folds of the chains in :func:`held_out_weights`.
PREDICTION_FOLDS = 10

#: A proposal's fit to particles and their chains: its components, their
#: weights and the coordinates it shifts (the fits of
#: :mod:`avrisk.rare.particle_shifts` with their settings bound).
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
    fit_variances: bool


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
        ``f`` falls (:func:`~avrisk.rare.particle_shifts.slope_direction`)
        rather than per coordinate.
    variances : bool
        Whether the components also fit each shifted coordinate's variance
        (:class:`~avrisk.rare.families.standard_space_normal.StandardSpaceNormal`).
    held_out : HeldOutWeights
        What the particles' importance weights ``p0 / q`` under fits that did
        not see them predict of the importance-sampling stage, before it is
        drawn (:func:`held_out_weights`).
    """

    proposal: MixtureProposal
    threshold: float
    n_shifted: int
    along_slope: bool = False
    variances: bool = False
    held_out: HeldOutWeights = HeldOutWeights(float("nan"), float("nan"))


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
        A unit direction in which ``f`` falls
        (:func:`~avrisk.rare.particle_shifts.slope_direction`): one
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
    fit_along = (
        None
        if along is None
        else functools.partial(fit_along_direction, base=base, along=along)
    )

    def per_coordinate(threshold: float, k: int) -> Fitter:
        """:func:`fit_per_coordinate` with its threshold and components set."""
        return functools.partial(
            fit_per_coordinate,
            base=base,
            allowed=allowed,
            threshold=threshold,
            k=k,
            min_weight=settings.min_weight,
            rng=rng,
        )

    choice = choose_fit(
        ChainHalves.of(z, chain),
        per_coordinate,
        settings.n_components,
        fit_along,
        settings.fit_variances,
    )
    components, weights, shifted = choice.fitter(z, chain)
    components, weights = with_light_regions(z, components, weights, shifted, base, rng)
    if choice.variances:  # one structure, so that a run directory records it
        components = [as_normal(c) for c in components]
    proposal = MixtureProposal(components, weights, base, settings.defensive)
    return ParticleFit(
        proposal,
        choice.threshold,
        int(np.count_nonzero(shifted)),
        along_slope=choice.along_slope,
        variances=choice.variances,
        held_out=held_out_weights(
            z, chain, choice.fitter, base, settings.defensive, rng
        ),
    )


class ChainHalves(NamedTuple):
    """The particles in two halves of the chains, each scored by a fit to the other.

    Chains are numbered in the order of their ancestors, so the halves (the
    lower and the upper numbers) descend from different draws of ``P0`` and
    are close to independent.

    Attributes
    ----------
    z : ndarray of shape (n, D)
        The particles in standard-normal space.
    chain : ndarray of int, shape (n,)
        Each particle's chain.
    first : ndarray of bool, shape (n,)
        The particles of the first half.
    """

    z: FloatArray
    chain: np.ndarray
    first: np.ndarray

    @classmethod
    def of(cls, z: FloatArray, chain: np.ndarray) -> ChainHalves:
        """The halves of the chains ``chain`` (the lower numbers first)."""
        return cls(z, chain, chain < (chain.max() + 1) / 2)

    def both_held(self) -> bool:
        """Whether each half holds particles (else nothing can be scored)."""
        return bool(self.first.any() and not self.first.all())

    def log_likelihoods(self, fitter: Fitter) -> FloatArray:
        """Each particle's log-likelihood under the fit to the other half, (n,)."""
        return cross_fitted_log_ratios(
            self.z,
            self.chain,
            (~self.first, self.first),
            lambda p, c: fitter(p, c)[:2],
        )

    def summed(self, scores: FloatArray) -> float:
        """Mean held-out log-likelihood of each half, summed over the halves."""
        return float(scores[~self.first].mean() + scores[self.first].mean())

    def clearly_better(self, a: FloatArray, b: FloatArray) -> bool:
        """Whether held-out scores ``a`` beat ``b`` by two standard errors.

        The paired differences' mean over particles, its standard error from
        blocks of chains (:func:`block_means`, the chains' correlation in it).
        """
        mean, stderr = block_means((a - b)[:, None], self.chain)
        return bool(mean[0] > 2.0 * np.nan_to_num(stderr[0], nan=np.inf))


class FitChoice(NamedTuple):
    """The fit :func:`choose_fit` chose, and what it is.

    Attributes
    ----------
    fitter : callable
        The chosen fit.
    threshold : float
        Its threshold in standard errors (0 along the slope).
    along_slope : bool
        Whether it is the shift along the slope.
    variances : bool
        Whether its components also fit each shifted coordinate's variance.
    """

    fitter: Fitter
    threshold: float
    along_slope: bool = False
    variances: bool = False


def choose_fit(
    halves: ChainHalves,
    per_coordinate: Callable[[float, int], Fitter],
    n_components: int,
    fit_along: Fitter | None,
    fit_variances: bool,
) -> FitChoice:
    """The fit whose halves score the other half's particles best.

    First the threshold (one component; ties to the sparsest, the first of
    ``THRESHOLDS``), then the number of components from 1 to
    ``n_components`` (ties to the fewest), then, with ``fit_variances``, the
    same components with their coordinates' variances fitted too
    (:func:`~avrisk.rare.particle_shifts.with_fitted_variances`) if that is
    clearly better, then the shift along the slope if it is clearly better
    than the fit so far. A close call goes to the simpler fit: better means
    by two standard errors of the paired difference
    (:meth:`ChainHalves.clearly_better`). With every particle in one half,
    nothing is scored: the sparsest threshold with one component.

    Parameters
    ----------
    halves : ChainHalves
        The particles and their chains, halved.
    per_coordinate : callable
        ``per_coordinate(threshold, k)``: the per-coordinate fitter.
    n_components : int
        Most components tried.
    fit_along : callable or None
        The fitter along ``f``'s slope, if there is one.
    fit_variances : bool
        Whether fitted variances are a candidate.

    Returns
    -------
    FitChoice
    """
    threshold = THRESHOLDS[0]
    if not halves.both_held():
        return FitChoice(per_coordinate(threshold, 1), threshold)
    # max keeps the first of ties
    threshold = max(
        THRESHOLDS,
        key=lambda t: halves.summed(halves.log_likelihoods(per_coordinate(t, 1))),
    )
    scores = {
        k: halves.log_likelihoods(per_coordinate(threshold, k))
        for k in range(1, n_components + 1)
    }
    k = max(scores, key=lambda k: halves.summed(scores[k]))
    choice = FitChoice(per_coordinate(threshold, k), threshold)
    best = scores[k]
    if fit_variances:
        # the coordinates whose variance alone is off count only here
        scaled_threshold = max(
            THRESHOLDS,
            key=lambda t: halves.summed(
                halves.log_likelihoods(with_variances(per_coordinate(t, 1)))
            ),
        )
        scaled = with_variances(per_coordinate(scaled_threshold, k))
        scaled_scores = halves.log_likelihoods(scaled)
        if halves.clearly_better(scaled_scores, best):
            choice = FitChoice(scaled, scaled_threshold, variances=True)
            best = scaled_scores
    if fit_along is not None and halves.clearly_better(
        halves.log_likelihoods(fit_along), best
    ):
        return FitChoice(fit_along, 0.0, along_slope=True)
    return choice


def with_variances(fitter: Fitter) -> Fitter:
    """``fitter`` with each component's variances fitted around its shift."""

    def fit(
        points: FloatArray, point_chain: np.ndarray
    ) -> tuple[list[ExponentialFamily], FloatArray, np.ndarray]:
        return with_fitted_variances(points, point_chain, *fitter(points, point_chain))

    return fit


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
        log_joint = np.log(weights) + log_ratios_to_base(components, z[test])
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
