"""The learned-driver block of P0: the shipped xi prior as a FixedCovNormal."""

import numpy as np
import pytest
from scipy import sparse

from avrisk.agents.drivers.store import XiPrior
from avrisk.agents.drivers.xi import XI_DIM
from avrisk.rare import FixedCovNormal
from avrisk.scenario import xi_base_family


def test_the_xi_prior_becomes_a_fixed_covariance_normal_with_the_papers_box(rng):
    members = 0.01 * rng.standard_normal((5, XI_DIM))
    precision = sparse.csr_array(sparse.eye_array(XI_DIM) * 1e4)
    prior = XiPrior(members.mean(0), precision, members)
    fam = xi_base_family(prior)
    assert isinstance(fam, FixedCovNormal) and fam.dim == XI_DIM
    assert np.array_equal(fam.mean, prior.mean)
    assert np.all(fam.max_shift == 0.01)
    x = fam.sample(3, rng)
    assert x.shape == (3, XI_DIM) and np.isfinite(fam.log_prob(x)).all()
    moved = fam.project(prior.mean + 1.0)  # the CE update cannot leave the box
    assert np.allclose(moved.mean, prior.mean + 0.01)


def test_a_box_in_prior_standard_deviations_scales_with_each_coordinate(rng):
    members = 0.01 * rng.standard_normal((5, XI_DIM))
    sd = np.linspace(0.001, 0.1, XI_DIM)
    precision = sparse.csr_array(sparse.diags_array(1.0 / sd**2))
    prior = XiPrior(members.mean(0), precision, members)
    fam = xi_base_family(prior, max_shift=2.0, unit="prior_sd")
    np.testing.assert_allclose(fam.max_shift, 2.0 * sd, rtol=1e-9)
    moved = fam.project(prior.mean + 1.0)
    np.testing.assert_allclose(moved.mean, prior.mean + 2.0 * sd, rtol=1e-9)
    with pytest.raises(ValueError, match="unit"):
        xi_base_family(prior, unit="sd")
