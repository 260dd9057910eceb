"""A mixture proposal's components as control variates of importance sampling.

Importance sampling from a mixture ``q = sum_j alpha_j q_j`` (the components
of a :class:`~avrisk.rare.mixture_em.MixtureProposal` and its defensive
``P0``) draws a random number of samples from each component. Part of the
estimate's variance is that count's: on two disjoint failure regions, each
fitted by a component, a sample holding more draws from one component than
its share ``alpha_j`` over-counts that region. The ratios ``g_j(x) = q_j(x) /
q(x)`` have known means under ``q`` (``E_q[g_j] = 1``), are bounded (``g_j <=
1 / alpha_j``), and are large exactly where component ``j`` drew: as control
variates they remove that part (Owen & Zhou 2000, section 4).

The regression estimator: for responses ``y`` (per-sample terms ``w h`` of
one or more events), ordinary least squares of ``y`` on ``1`` and the
centred controls ``c = g - 1`` gives coefficients ``beta``; the controlled
terms ``t = y - c beta`` have the regression's intercept as their mean, and
their spread (with the fitted coefficients' degrees of freedom) as its
standard error. The ``g_j`` sum to one with the weights ``alpha_j``, so one
of them (the defensive ``P0``'s) is left out. The estimate is consistent, its
bias of order ``1 / n``.

References
----------
A. Owen, Y. Zhou. "Safe and effective importance sampling." Journal of the
American Statistical Association 95(449), 2000.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

from avrisk.rare.families.base import FloatArray
from avrisk.rare.mixture_em import MixtureProposal

__all__ = ["ControlledTerms", "controlled_terms", "mixture_controls"]


class ControlledTerms(NamedTuple):
    """Responses less their fitted controls.

    Attributes
    ----------
    terms : ndarray of shape (n, m)
        ``t = y - c beta`` per response: their mean is the controlled
        estimate.
    ddof : int
        Degrees of freedom the fit used (``1 +`` the controls' rank): the
        ``ddof`` of the terms' spread.
    """

    terms: FloatArray
    ddof: int


def mixture_controls(proposal: Any, x: FloatArray) -> FloatArray:
    """The centred controls ``g_j(x) - 1`` of a mixture proposal, shape (n, J).

    Parameters
    ----------
    proposal : MixtureProposal or any other proposal
        What the samples were drawn from.
    x : ndarray of shape (n, D)
        The samples.

    Returns
    -------
    ndarray of shape (n, J)
        One column per component of a mixture (its defensive ``P0`` left
        out; with none, one component less); no column for any other
        proposal, or for a mixture of one term.

    Examples
    --------
    >>> from avrisk.rare import FixedCovNormal
    >>> base = FixedCovNormal(np.zeros(1), cov=np.eye(1))
    >>> left, right = base.project(np.array([-4.0])), base.project(np.array([4.0]))
    >>> q = MixtureProposal([left, right], [0.5, 0.5], base, defensive=0.1)
    >>> c = mixture_controls(q, q.sample(200_000, np.random.default_rng(0)))
    >>> c.shape, bool(np.abs(c.mean(axis=0)).max() < 0.02)  # mean 0 under q
    ((200000, 2), True)
    """
    n = len(x)
    if not isinstance(proposal, MixtureProposal):
        return np.empty((n, 0))
    log_q = proposal.log_prob(x)
    components = list(proposal.components)
    if proposal.defensive == 0.0:
        components = components[:-1]  # they sum to one with the weights
    if not components:
        return np.empty((n, 0))
    return np.stack([np.exp(c.log_prob(x) - log_q) - 1.0 for c in components], axis=1)


def controlled_terms(responses: FloatArray, controls: FloatArray) -> ControlledTerms:
    """Each response less its least-squares fit on the controls.

    Parameters
    ----------
    responses : ndarray of shape (n, m)
        Per-sample terms ``y`` of ``m`` estimates (``w h`` of ``m`` events).
    controls : ndarray of shape (n, J)
        Centred controls (:func:`mixture_controls`), mean 0 under the
        sampling distribution.

    Returns
    -------
    ControlledTerms
        The responses unchanged (``ddof`` 1) without controls, with constant
        ones, or with too few samples for the fit.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> c = rng.standard_normal((1000, 1))
    >>> y = 2.0 + 3.0 * c + 0.1 * rng.standard_normal((1000, 1))
    >>> fit = controlled_terms(y, c)
    >>> bool(fit.terms.std() < 0.11), fit.ddof
    (True, 2)
    """
    n, j = controls.shape
    if j == 0 or n <= j + 2:
        return ControlledTerms(responses, 1)
    design = np.column_stack([np.ones(n), controls])
    coef, _, rank, _ = np.linalg.lstsq(design, responses, rcond=None)
    if rank <= 1:  # constant controls (a component equal to the mixture)
        return ControlledTerms(responses, 1)
    return ControlledTerms(responses - controls @ coef[1:], int(rank))
