"""Mixtures of exponential-family members as proposals, fitted by weighted EM.

A :class:`MixtureProposal` is the importance-sampling proposal

    q = lam P0 + (1 - lam) sum_k pi_k q_k

of ``K`` members ``q_k`` of one structure (the base's family at other
parameters, or mean shifts of its standard normals,
:class:`~avrisk.rare.families.StandardSpaceShift`) and of the base ``P0``
itself with weight ``lam`` (defensive, :mod:`avrisk.rare.defensive`: every
weight ``p0 / q`` is at most ``1 / lam``). A sample is a row of shape (D,);
the members need not be normal: any family of :mod:`avrisk.rare.families`
(normals of a fixed covariance, scaled betas, their products) is fitted
through its sufficient statistic ``T(x)``, shape (S,), and its own CE
projection. Mixture cross-entropy (:mod:`avrisk.rare.mixture`) fits one to
each iteration's weighted elite, splitting + importance sampling
(:mod:`avrisk.rare.particle_fit`) to subset simulation's particles; both use
the steps below, which know nothing of where the weighted samples came from.

EM (:func:`fit_mixture`). The E-step gives each sample ``x_i`` (weight
``w_i``, the weights summing to one) its responsibilities ``r_ik`` from
``pi_k q_k(x_i)`` (from the sufficient statistics alone,
:func:`component_log_kernels`); the M-step gives each component the weighted
mean sufficient statistic ``m_k = sum_i w_i r_ik T(x_i) / sum_i w_i r_ik`` of
its samples, projected into the search box by the family's own CE projection
(``project(m_k)``: the maximum-likelihood fit), and the weight ``pi_k =
sum_i w_i r_ik``. The steps repeat until the weighted log-likelihood gains
less than ``EM_TOLERANCE``.

Initialisation (:func:`seed_components`). The samples are split into groups:
weighted k-means++ seeding (:func:`kmeans_plus_plus`) draws ``OVERSEEDING``
times ``n_components`` centres in the standardised sufficient-statistic
space, the first one a sample drawn by weight, each next one with
probability proportional to weight times squared distance to the nearest
centre so far, so distant groups of samples, the candidate modes, get a
centre each; every sample joins its nearest centre. The groups are merged
pairwise (Ward: least rise of the k-means potential first) down to
``n_components``, so a large group's several centres go back together before
a small distant group loses its own. Each group's M-step gives its
component, and EM refines them.

Death and merging. The mixture weights are the components' shares of the
sample weight, with a floor: an M-step that leaves a component less than
``min_weight`` removes it (it explains too few samples for its fit to be
trusted, and samples spent on it are mostly wasted). Two components whose
symmetric Kullback-Leibler divergence ``(theta_i - theta_j)^T (m_i - m_j)``
is below ``MERGE_DIVERGENCE`` are one (:func:`merge_overlapping`): they are
replaced by the projection of their weight-averaged mean parameters (on a
single mode, EM pulls the components together, and they merge).

References
----------
N. Kurtz, J. Song. "Cross-entropy-based adaptive importance sampling using
Gaussian mixture." Structural Safety 42, 2013.
S. Geyer, I. Papaioannou, D. Straub. "Cross entropy-based importance sampling
using Gaussian densities revisited." Structural Safety 76, 2019.
D. Arthur, S. Vassilvitskii. "k-means++: the advantages of careful seeding."
SODA 2007.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, NamedTuple

import numpy as np
from scipy.special import logsumexp

from avrisk.rare.families.base import ExponentialFamily, FloatArray

#: EM stops once an iteration gains less than this in weighted mean log-likelihood.
EM_TOLERANCE = 1e-6
#: At most this many EM iterations per search iteration (the next one goes on from
#: where it stopped).
MAX_EM_STEPS = 50
#: Components closer than this symmetric Kullback-Leibler divergence merge (for
#: normals of a fixed covariance: means less than 1 standard deviation apart).
MERGE_DIVERGENCE = 1.0
#: k-means++ centres per component at the first iteration (:func:`seed_components`).
OVERSEEDING = 3


class MixtureProposal:
    """``q = lam P0 + (1 - lam) sum_k pi_k q_k`` (see the module docstring).

    Parameters
    ----------
    components : sequence of ExponentialFamily
        The ``q_k``, all of one structure (the base's, or its standard-space
        shifts).
    weights : array_like of shape (K,)
        Their weights ``pi_k``, positive (normalised to sum to one).
    base : ExponentialFamily
        ``P0``.
    defensive : float
        Weight ``lam`` of ``P0``, in [0, 1).

    Examples
    --------
    >>> import numpy as np
    >>> from avrisk.rare import FixedCovNormal
    >>> base = FixedCovNormal(np.zeros(1), cov=np.eye(1))
    >>> left, right = base.project(np.array([-4.0])), base.project(np.array([4.0]))
    >>> q = MixtureProposal([left, right], [0.5, 0.5], base, defensive=0.1)
    >>> x = q.sample(100_000, np.random.default_rng(0))
    >>> w = np.exp(base.log_prob(x) - q.log_prob(x))  # p0 / q, mean 1, at most 10
    >>> bool(w.max() <= 10.0), bool(abs(w.mean() - 1.0) < 0.03)
    (True, True)
    """

    def __init__(
        self,
        components: Sequence[ExponentialFamily],
        weights: Any,
        base: ExponentialFamily,
        defensive: float,
    ) -> None:
        weights = np.asarray(weights, dtype=np.float64)
        if len(components) == 0 or weights.shape != (len(components),):
            raise ValueError(
                f"need one weight per component; got {weights.shape} weights for "
                f"{len(components)} components"
            )
        if not (weights > 0).all() or not np.isfinite(weights).all():
            raise ValueError(f"weights must be positive; got {weights}")
        if not 0.0 <= defensive < 1.0:
            raise ValueError(f"defensive must be in [0, 1); got {defensive}")
        if any(c.dim != base.dim for c in components):
            raise ValueError("every component must have the base's dimension")
        self.components = tuple(components)
        self.weights = weights / weights.sum()
        self.base = base
        self.defensive = float(defensive)

    @property
    def dim(self) -> int:
        """Dimension ``D`` of a sample."""
        return self.base.dim

    @property
    def n_components(self) -> int:
        """Number ``K`` of components besides the defensive ``P0``."""
        return len(self.components)

    def sample(self, n: int, rng: np.random.Generator) -> FloatArray:
        """Draw ``n`` samples, shape (n, D).

        Component choices, ``P0``'s draws and each component's draws come from
        separate children of ``rng``, so row ``i`` does not depend on ``n``
        (the engine's prefix consistency).
        """
        choose, from_base, *from_components = rng.spawn(2 + self.n_components)
        shares = (1.0 - self.defensive) * self.weights
        edges = self.defensive + np.concatenate([[0.0], np.cumsum(shares)[:-1]])
        which = np.searchsorted(edges, choose.random(n), side="right")  # 0: P0
        x = np.empty((n, self.dim))
        if self.defensive > 0:
            use = which == 0
            x[use] = self.base.sample(n, from_base)[use]
        for k, (component, stream) in enumerate(
            zip(self.components, from_components, strict=True), start=1
        ):
            use = which == k
            x[use] = component.sample(n, stream)[use]
        return x

    def log_prob(self, x: FloatArray) -> FloatArray:
        """Log-density of the mixture (a log-sum-exp of its terms), shape (n,)."""
        terms = [
            math.log1p(-self.defensive) + math.log(pi) + c.log_prob(x)
            for c, pi in zip(self.components, self.weights, strict=True)
        ]
        if self.defensive > 0:
            terms.append(math.log(self.defensive) + self.base.log_prob(x))
        return logsumexp(np.stack(terms), axis=0)

    def sufficient_stat(self, x: FloatArray) -> FloatArray:
        """The components' common sufficient statistic ``T(x)``, shape (n, S)."""
        return self.components[0].sufficient_stat(x)

    def to_dict(self) -> dict[str, Any]:
        """Weights, defensive share and the components' descriptions."""
        return {
            "family": "Mixture",
            "defensive": self.defensive,
            "weights": self.weights.tolist(),
            "components": [c.to_dict() for c in self.components],
        }


def component_log_kernels(
    components: Sequence[ExponentialFamily], stats: FloatArray
) -> FloatArray:
    """``theta_k^T T(x_i) - A(theta_k)``: ``log q_k(x_i)`` less ``log h(x_i)``.

    Components of one structure share the carrier ``h``, so these differ from
    their log-densities by the same amount per sample: enough for
    responsibilities and for comparing fits.

    Parameters
    ----------
    components : sequence of ExponentialFamily
        ``K`` members of one structure.
    stats : ndarray of shape (n, S)
        Sufficient statistics ``T(x_i)``.

    Returns
    -------
    ndarray of shape (n, K)
    """
    theta = np.stack([c.natural_params for c in components])
    log_partition = np.array([c.log_partition() for c in components])
    return stats @ theta.T - log_partition


class MixtureFit(NamedTuple):
    """Components fitted by :func:`fit_mixture`.

    Attributes
    ----------
    components : tuple of ExponentialFamily
        The ``K'`` surviving components (``K' <= K``).
    weights : ndarray of shape (K',)
        Their mixture weights, summing to one.
    targets : ndarray of shape (K', S)
        The mean statistics ``m_k`` of the last M-step (before projection).
    origin : ndarray of int, shape (K',)
        Index of the starting component each one grew from.
    """

    components: tuple[ExponentialFamily, ...]
    weights: FloatArray
    targets: FloatArray
    origin: np.ndarray


def fit_mixture(
    components: Sequence[ExponentialFamily],
    weights: FloatArray,
    stats: FloatArray,
    elite_weights: FloatArray,
    min_weight: float,
) -> MixtureFit:
    """Weighted EM from the given components (step 3 of the module docstring).

    Each M-step projects a component's weighted mean statistic with the
    family's CE projection, so every component stays in the search box, and
    removes the components left with less than ``min_weight`` of the elite
    weight (never the heaviest).

    Parameters
    ----------
    components : sequence of ExponentialFamily
        ``K`` starting components, of one structure.
    weights : ndarray of shape (K,)
        Their starting weights, positive.
    stats : ndarray of shape (n, S)
        Sufficient statistics of the elite samples.
    elite_weights : ndarray of shape (n,)
        Their self-normalised importance weights, positive, summing to one.
    min_weight : float
        Share of the elite weight below which a component dies.

    Returns
    -------
    MixtureFit
    """
    components = list(components)
    log_pi = np.log(weights)
    origin = np.arange(len(components))
    previous = -math.inf
    for _ in range(MAX_EM_STEPS):
        log_joint = log_pi + component_log_kernels(components, stats)
        log_mixture = logsumexp(log_joint, axis=1)
        log_likelihood = float(elite_weights @ log_mixture)
        mass = elite_weights[:, None] * np.exp(log_joint - log_mixture[:, None])
        shares = mass.sum(axis=0)
        alive = shares >= min_weight
        alive[np.argmax(shares)] = True
        targets = (mass[:, alive].T @ stats) / shares[alive, None]
        components = [
            components[k].project(m)
            for k, m in zip(np.flatnonzero(alive), targets, strict=True)
        ]
        log_pi = np.log(shares[alive] / shares[alive].sum())
        origin = origin[alive]
        if log_likelihood - previous < EM_TOLERANCE:
            break
        previous = log_likelihood
    return MixtureFit(tuple(components), np.exp(log_pi), targets, origin)


def kmeans_plus_plus(
    points: FloatArray, weights: FloatArray, k: int, rng: np.random.Generator
) -> np.ndarray:
    """Weighted greedy k-means++ seeding (Arthur & Vassilvitskii 2007).

    The first centre is a point drawn by weight; each next one is the best
    (lowest weighted potential ``sum_i w_i min_c |z_i - c|^2``) of ``2 + ln k``
    points drawn with probability proportional to weight times squared
    distance to the nearest centre so far. Stops early when every point is a
    centre's duplicate.

    Parameters
    ----------
    points : ndarray of shape (n, S)
    weights : ndarray of shape (n,)
        Non-negative, not all zero.
    k : int
        Centres wanted.
    rng : numpy.random.Generator

    Returns
    -------
    ndarray of int, shape (k',)
        Indices of the centres among ``points`` (``k' <= k``).
    """
    trials = 2 + int(math.log(k))
    centres = [int(rng.choice(len(points), p=weights / weights.sum()))]
    nearest = ((points - points[centres[0]]) ** 2).sum(axis=1)
    while len(centres) < k:
        potential = weights * nearest
        if potential.sum() <= 0:
            break
        candidates = rng.choice(len(points), trials, p=potential / potential.sum())
        distances = np.stack(
            [((points - points[c]) ** 2).sum(axis=1) for c in candidates]
        )
        closer = np.minimum(nearest, distances)
        best = int(np.argmin(closer @ weights))
        centres.append(int(candidates[best]))
        nearest = closer[best]
    return np.array(centres)


def seed_components(
    base: ExponentialFamily,
    stats: FloatArray,
    elite_weights: FloatArray,
    n_components: int,
    rng: np.random.Generator,
) -> tuple[list[ExponentialFamily], FloatArray]:
    """Starting components: the elite split into groups around k-means++ centres.

    In the sufficient-statistic space standardised by the weighted standard
    deviations, k-means++ draws ``OVERSEEDING * n_components`` centres and
    every elite joins its nearest one. Groups are then merged pairwise, the
    pair whose union raises the weighted k-means potential least first (Ward),
    down to ``n_components``: the several centres that a large group of elites
    draws go back together before a small distant group (a mode with few
    elites at the first level) loses its own. Each group's weighted mean
    statistic, projected by ``base``, is a component with the group's weight.

    Parameters
    ----------
    base : ExponentialFamily
        The structure of the components.
    stats : ndarray of shape (n, S)
        Sufficient statistics of the elite samples.
    elite_weights : ndarray of shape (n,)
        Their self-normalised importance weights, positive.
    n_components : int
        Components wanted (fewer if the elite has fewer distinct points).
    rng : numpy.random.Generator

    Returns
    -------
    components : list of ExponentialFamily
    weights : ndarray of shape (K,)
    """
    centre = elite_weights @ stats
    spread = np.sqrt(elite_weights @ (stats - centre) ** 2)
    standard = (stats - centre) / np.where(spread > 0, spread, 1.0)
    seeds = standard[
        kmeans_plus_plus(standard, elite_weights, OVERSEEDING * n_components, rng)
    ]
    # one centre at a time: an (n, centres, S) block would not fit for large S
    distances = np.stack([((standard - c) ** 2).sum(axis=1) for c in seeds], axis=1)
    nearest = np.argmin(distances, axis=1)
    members = np.eye(len(seeds), dtype=bool)[nearest].T  # (groups, n)
    shares = members @ elite_weights
    means = (members * elite_weights) @ standard / shares[:, None]
    while len(shares) > n_components:
        gap = ((means[:, None] - means[None]) ** 2).sum(-1)
        cost = np.outer(shares, shares) / np.add.outer(shares, shares) * gap
        np.fill_diagonal(cost, np.inf)
        i, j = np.unravel_index(np.argmin(cost), cost.shape)
        means[i] = (shares[i] * means[i] + shares[j] * means[j]) / (
            shares[i] + shares[j]
        )
        shares[i] += shares[j]
        members[i] |= members[j]
        means, shares, members = (
            np.delete(a, j, axis=0) for a in (means, shares, members)
        )
    targets = (members * elite_weights) @ stats / shares[:, None]
    return [base.project(m) for m in targets], shares


def merge_overlapping(
    components: Sequence[ExponentialFamily], weights: FloatArray
) -> tuple[list[ExponentialFamily], FloatArray]:
    """Merge the closest pair while its divergence is below ``MERGE_DIVERGENCE``.

    The symmetric Kullback-Leibler divergence of two members of one
    exponential family is ``(theta_i - theta_j)^T (m_i - m_j)`` (natural and
    mean parameters). A merged pair is the projection of the weight-average of
    their mean parameters (the fit to their union), with the sum of weights.

    Returns
    -------
    components : list of ExponentialFamily
    weights : ndarray of shape (K',)
    """
    components, weights = list(components), np.array(weights, dtype=np.float64)
    while len(components) > 1:
        theta = np.stack([c.natural_params for c in components])
        mean = np.stack([c.mean_param() for c in components])
        divergence = (
            (theta[:, None] - theta[None]) * (mean[:, None] - mean[None])
        ).sum(-1)
        np.fill_diagonal(divergence, np.inf)
        i, j = np.unravel_index(np.argmin(divergence), divergence.shape)
        if divergence[i, j] >= MERGE_DIVERGENCE:
            break
        pooled = (weights[i] * mean[i] + weights[j] * mean[j]) / (
            weights[i] + weights[j]
        )
        components[i] = components[i].project(pooled)
        weights[i] += weights[j]
        del components[j]
        weights = np.delete(weights, j)
    return components, weights
