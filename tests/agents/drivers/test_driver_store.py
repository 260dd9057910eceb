import numpy as np
import pytest
from scipy import linalg, sparse

from avrisk.agents.drivers.network import HIDDEN_SIZES
from avrisk.agents.drivers.store import (
    DRIVER_NET_FILE,
    XI_PRIOR_FILE,
    XiPrior,
    default_drivers_dir,
    load_driver_net,
    load_xi_prior,
)
from avrisk.agents.drivers.xi import XI_DIM


def small_prior(rng):
    members = rng.standard_normal((5, XI_DIM))
    p = sparse.eye_array(XI_DIM, format="lil") * 2.0
    p[0, 1] = p[1, 0] = 0.5
    return XiPrior(members.mean(0), sparse.csr_array(p), members, {"alpha": 0.1})


def test_an_xi_prior_round_trips_through_npz_without_pickle(tmp_path, rng):
    prior = small_prior(rng)
    prior.save(tmp_path / "p.npz")
    back = XiPrior.load(tmp_path / "p.npz")
    assert np.array_equal(back.mean, prior.mean)
    assert np.array_equal(back.members, prior.members)
    assert (back.precision != prior.precision).nnz == 0
    assert back.meta == {"alpha": 0.1}
    assert back.sparsity == pytest.approx(1 - 2 / (XI_DIM * XI_DIM - XI_DIM))


def test_an_xi_prior_of_the_wrong_dimension_is_refused(rng):
    with pytest.raises(ValueError, match="mean must have shape"):
        XiPrior(
            np.zeros(3), sparse.eye_array(XI_DIM, format="csr"), np.zeros((2, XI_DIM))
        )


shipped = pytest.mark.skipif(
    not (default_drivers_dir() / XI_PRIOR_FILE).is_file()
    or not (default_drivers_dir() / DRIVER_NET_FILE).is_file(),
    reason="no shipped driver files yet (run avrisk.learning.train_drivers)",
)


@shipped
def test_the_shipped_network_has_the_paper_architecture():
    net = load_driver_net()
    assert (net.fc1.in_features, net.fc1.out_features) == (51, HIDDEN_SIZES[0])
    assert (net.fc2.out_features, net.last.out_features) == (100, 4)
    assert not net.training


@shipped
def test_the_shipped_xi_prior_is_sparse_positive_definite_and_centred_on_the_ensemble():
    prior = load_xi_prior()
    p = prior.precision.toarray()
    assert np.array_equal(p, p.T)
    linalg.cholesky(p)  # raises unless positive definite
    assert prior.sparsity > 0.9
    assert prior.members.shape[0] >= 2
    assert np.allclose(prior.mean, prior.members.mean(axis=0))
