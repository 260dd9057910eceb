"""The simulator as the engine's black box: f and the per-rollout outcomes."""

import numpy as np

from avrisk.assembly import (
    EVENT_COLUMNS,
    FACT_COLUMNS,
    SimulationObjective,
    base_distribution,
)
from avrisk.rare.problem import chunk_rng, sample_seeds
from avrisk.scenario import load_spec


def test_the_objective_returns_f_flags_status_and_crash_facts_per_rollout():
    spec = load_spec("highway_idm")
    spec = spec.model_copy(
        update={"simulation": spec.simulation.model_copy(update={"horizon": 1.0})}
    )
    objective = SimulationObjective(spec)
    x = base_distribution(spec).sample(4, chunk_rng(0, 0, 0))
    out = objective(x, sample_seeds(0, 0, np.arange(4)))
    assert set(out) == {"f", *EVENT_COLUMNS, *FACT_COLUMNS}
    assert out["f"].dtype == np.float64 and out["f"].shape == (4,)
    assert {k: out[k].dtype for k in FACT_COLUMNS} == {
        "status": np.int8, "collision_with": np.int16, "contact": np.int8
    }  # fmt: skip
    assert (out["status"] == 0).all()
    np.testing.assert_array_equal(out["collision_with"] >= 0, out["crash"])
    np.testing.assert_array_equal(out["contact"] > 0, out["crash"])
