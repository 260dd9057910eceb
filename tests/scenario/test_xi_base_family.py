"""The learned-driver block of P0: the shipped xi prior as a FixedCovNormal."""

import numpy as np
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
