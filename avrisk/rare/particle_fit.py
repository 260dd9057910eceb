"""The importance-sampling proposal fitted to subset simulation's particles.

Step 3 of :mod:`avrisk.rare.splitting_importance` (its module docstring says
what the fit does and why): mean shifts of the base's standard normals on the
coordinates the particles say something about, with their variances where
that clearly fits better, components
chosen by the held-out likelihood of one half of the chains under a fit to
the other half, shrunk by their noise, plus a component for each region the
fit leaves out. The shifts themselves are fitted in
:mod:`avrisk.rare.particle_shifts`, and what the particles predict of a fit's
sample in :mod:`avrisk.rare.particle_predictions`; this module chooses among
the fits. It knows nothing of how the particles were made: particles of
``P0(. | f <= gamma)`` in standard-normal space, and the chain of each.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Literal, NamedTuple, Protocol

import numpy as np

from avrisk.rare.chain_moments import block_means
from avrisk.rare.families.base import ExponentialFamily, FloatArray
from avrisk.rare.mixture_em import MixtureProposal
from avrisk.rare.particle_predictions import (
    Fitter,
    HeldOutWeights,
    cross_fitted_log_ratios,
    held_out_weights,
)
from avrisk.rare.particle_shifts import (
    as_normal,
    fit_along_direction,
    fit_per_coordinate,
    with_fitted_variances,
    with_light_regions,
)

__all__ = [
    "THRESHOLDS",
    "ChainHalves",
    "FitChoice",
    "ParticleFit",
    "ProposalSettings",
    "choose_fit",
    "particle_proposal",
]

#: Candidate thresholds, in standard errors, beyond which a coordinate's particle
#: mean (or mean square) counts as informative (step 3 of the module
#: docstring), the sparsest first (ties of the held-out score go to it); 0
#: keeps every coordinate.
THRESHOLDS = (4.0, 3.0, 2.5, 2.0, 1.5, 0.0)


class ProposalSettings(Protocol):
    """The settings the fit reads.

    Those of :class:`~avrisk.rare.splitting_importance.SplittingISSettings`.
    """

    n_components: int
    min_weight: float
    defensive: float
    shift: Literal["all", "searched"]
    fit_variances: bool


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

    def best_threshold(self, fitter_at: Callable[[float], Fitter]) -> float:
        """The one of ``THRESHOLDS`` whose fit scores best (ties to the sparsest)."""
        # max keeps the first of ties
        return max(
            THRESHOLDS, key=lambda t: self.summed(self.log_likelihoods(fitter_at(t)))
        )

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
    threshold = halves.best_threshold(lambda t: per_coordinate(t, 1))
    scores = {
        k: halves.log_likelihoods(per_coordinate(threshold, k))
        for k in range(1, n_components + 1)
    }
    k = max(scores, key=lambda k: halves.summed(scores[k]))
    choice = FitChoice(per_coordinate(threshold, k), threshold)
    best = scores[k]
    if fit_variances:
        # the coordinates whose variance alone is off count only here
        scaled_threshold = halves.best_threshold(
            lambda t: with_variances(per_coordinate(t, 1))
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
