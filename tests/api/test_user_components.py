"""A user's estimator and safety measure, one module each, run through the API.

Issue 43: adding an estimator, an ego, a backend or a safety measure is one
module plus tests. The ego is ``tests/user_components.py`` (``HoldSpeedEgo``,
run in ``tests/cli/test_user_ego.py`` and ``tests/api/test_api.py``), the
backend ``tests/user_backend.py`` (run in ``tests/api/test_backends.py``);
here are the estimator (``tests/user_estimator.py``) and the safety measure
(``tests/user_safety.py``).
"""

import copy
import importlib
import math
import sys

import numpy as np
import pyarrow.parquet as pq
import pytest
import torch

import avrisk
from avrisk.pipeline.layout import SAMPLES_FILE
from avrisk.rare import FixedCovNormal, estimator
from avrisk.sim.state import VehicleState
from tests.scenario_files import shortened_scenario
from tests.user_safety import MinCentreDistance

FAST = dict(n_final=64, batch_size=64, seed=4, failures=0)


@pytest.fixture
def plain_mc(monkeypatch):
    """``tests.user_estimator`` imported afresh; its registration gone after."""
    for table in ("_factories", "_descriptions"):
        own = copy.copy(getattr(estimator.ESTIMATORS, table))
        assert "plain_mc" not in own, "tests.user_estimator was imported elsewhere"
        monkeypatch.setattr(estimator.ESTIMATORS, table, own)
    monkeypatch.delitem(sys.modules, "tests.user_estimator", raising=False)
    module = importlib.import_module("tests.user_estimator")
    yield module
    sys.modules.pop("tests.user_estimator", None)


def test_a_users_estimator_is_registered_by_importing_its_module(plain_mc):
    assert "plain_mc" in estimator.estimator_names()
    assert estimator.get_estimator("plain_mc", n_final=5).describe() == (
        "plain MC, 5 samples"
    )


def test_a_users_estimator_estimates_an_exact_probability(plain_mc):
    base = FixedCovNormal(np.zeros(2), cov=np.eye(2))
    gamma, n = -2.0, 20_000
    exact = 0.5 * math.erfc(2.0 / math.sqrt(2.0))  # P(N(0, 1) <= -2)

    def f(x):
        return x[:, 0]

    est = avrisk.rare.estimate("plain_mc", f, base, gamma, n_final=n, seed=1)
    assert est.n_evals == n
    assert abs(est.p - exact) < 4 * est.stderr
    g = est.by_gamma[gamma]
    half = plain_mc.Z95 * g.stderr
    assert g.ci == pytest.approx((g.p - half, g.p + half))
    # the same draws of P0 as the bundled naive Monte Carlo, at the same seed
    naive = avrisk.rare.estimate("naive", f, base, gamma, n_final=n, seed=1)
    assert g.n_hits == naive.by_gamma[gamma].n_hits


def test_a_users_estimator_runs_a_scenario_as_a_bundled_one_does(tmp_path, plain_mc):
    scenario = shortened_scenario(tmp_path, 1.0)
    gammas = dict(gamma=3.0, gamma_test=(5.0,))
    ran = avrisk.estimate(
        scenario, method="plain_mc", out=tmp_path / "plain", **gammas, **FAST
    )
    naive = avrisk.estimate(
        scenario, method="naive", out=tmp_path / "naive", **gammas, **FAST
    )
    assert ran.report is not None and ran.report.is_file()
    assert ran.estimate["n_evals"] == naive.estimate["n_evals"] == FAST["n_final"]
    assert ran.by_gamma == naive.by_gamma  # the same rollouts, counted alike
    assert ran.by_gamma[5.0] > 0, "the check compares no hits"
    assert ran.estimate["method"] == "plain_mc"


def test_a_users_safety_measure_is_the_distance_between_centres():
    state = VehicleState.from_rows(
        [[0.0, 0.0, 0.0, 20.0, 4.0, 2.0], [3.0, 4.0, 0.0, 10.0, 4.0, 2.0],
         [60.0, 0.0, 0.0, 10.0, 4.0, 2.0]]
    )  # fmt: skip
    assert MinCentreDistance().instant(state).tolist() == [5.0]
    assert MinCentreDistance(cap=2.0).instant(state).tolist() == [2.0]
    measure = MinCentreDistance()
    carry = measure.init(torch.tensor([5.0, 7.0]))
    carry = measure.update(carry, torch.tensor([4.0, 1.0]), torch.tensor([True, False]))
    assert measure.finalize(carry).tolist() == [4.0, 7.0]


def test_a_users_safety_measure_defines_f_of_a_scenario_run(tmp_path):
    cap = 40.0
    safety = {"measure": "tests.user_safety:MinCentreDistance", "params": {"cap": cap}}
    scenario = shortened_scenario(tmp_path, 1.0, safety=safety)
    gamma = 12.0  # [m]
    result = avrisk.estimate(
        scenario, method="naive", out=tmp_path / "run", gamma=gamma, gamma_test=(),
        **FAST,
    )  # fmt: skip
    f = pq.read_table(result.path / SAMPLES_FILE)["f"].to_numpy()
    assert f.size == FAST["n_final"]
    assert (f > 0).all() and (f <= cap).all()
    assert result.spec.safety.measure == safety["measure"]
    assert result.p == np.count_nonzero(f <= gamma) / f.size
    ttc = avrisk.estimate(
        shortened_scenario(tmp_path, 1.0, file="ttc.yaml"),
        method="naive",
        out=tmp_path / "ttc",
        gamma_test=(),
        **FAST,
    )
    ttc_f = pq.read_table(ttc.path / SAMPLES_FILE)["f"].to_numpy()
    assert not np.allclose(f, ttc_f), "f is the scenario's own measure, not the user's"
