"""The mixture's components as control variates (avrisk.rare.mixture_controls)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import norm

from avrisk.rare import FixedCovNormal
from avrisk.rare.mixture_controls import controlled_terms, mixture_controls
from avrisk.rare.mixture_em import MixtureProposal

#: Two disjoint failure sets, u_1 >= 3 and u_1 <= -3.5, and a component each.
BASE = FixedCovNormal(np.zeros(2), cov=np.eye(2))
P_A, P_B = norm.sf(3.0), norm.sf(3.5)
PROPOSAL = MixtureProposal(
    [BASE.project(np.array([3.3, 0.0])), BASE.project(np.array([-3.8, 0.0]))],
    [0.5, 0.5],
    BASE,
    defensive=0.1,
)


def estimates(seed: int, n: int = 2000) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Plain and controlled estimates of (p_A, p_B - p_A), and the controlled se."""
    x = PROPOSAL.sample(n, np.random.default_rng(seed))
    w = np.exp(BASE.log_prob(x) - PROPOSAL.log_prob(x))
    a, b = w * (x[:, 0] >= 3.0), w * (x[:, 0] <= -3.5)
    y = np.stack([a, b - a], axis=1)
    fit = controlled_terms(y, mixture_controls(PROPOSAL, x))
    se = fit.terms.std(axis=0, ddof=fit.ddof) / np.sqrt(n)
    return y.mean(axis=0), fit.terms.mean(axis=0), se


def test_the_controls_are_one_per_component_and_centred():
    x = PROPOSAL.sample(100_000, np.random.default_rng(1))
    c = mixture_controls(PROPOSAL, x)
    assert c.shape == (100_000, 2)
    assert np.abs(c.mean(axis=0)).max() < 0.02
    # bounded: q_j / q <= 1 / ((1 - defensive) pi_j)
    assert (c <= 1.0 / 0.45 - 1.0 + 1e-12).all()


def test_other_proposals_have_no_controls():
    x = np.zeros((5, 2))
    assert mixture_controls(BASE, x).shape == (5, 0)
    one = MixtureProposal([BASE.project(np.array([3.0, 0.0]))], [1.0], BASE, 0.0)
    assert mixture_controls(one, x).shape == (5, 0)
    y = np.ones((5, 1))
    assert controlled_terms(y, np.empty((5, 0))) == (y, 1)
    assert controlled_terms(y, np.zeros((5, 1))).ddof == 1  # constant control


def test_controls_narrow_the_difference_of_two_regions_without_bias():
    runs = [estimates(seed) for seed in range(200)]
    plain = np.array([r[0] for r in runs])
    controlled = np.array([r[1] for r in runs])
    se = np.array([r[2] for r in runs])
    exact = np.array([P_A, P_B - P_A])
    # unbiased within the spread of the 200 means
    spread = controlled.std(axis=0, ddof=1)
    assert np.all(np.abs(controlled.mean(axis=0) - exact) < 3 * spread / np.sqrt(200))
    # the reported standard error is the spread's (known to about 5%)
    assert se.mean(axis=0) == pytest.approx(spread, rel=0.15)
    # the same samples, less the components' random counts: narrower (about
    # 0.92-0.93 of the plain spread here; each component also draws outside
    # its region, and that part stays)
    assert spread[1] < 0.97 * plain.std(axis=0, ddof=1)[1]
    # 95% intervals cover the exact values (binomial over 200 runs)
    covered = np.abs(controlled - exact) <= 1.96 * se
    assert covered.mean(axis=0).min() >= 0.9
