"""Recorded near-threshold rollouts of highway_idm, replayed on every device.

A rate of 2e-4 is decided by a few hundred rollouts in millions; an agreement
check on a thousand random rollouts sees none of them. These rows are the
lowest-``f`` rollouts of chunks of the draws behind issue 42's GPU reference
(``benchmarks/device_agreement.py fixture``): replayed on the CPU they must
give the recorded ``f`` bit for bit (a change of the scenario's rollouts shows
here first, and its references must then be computed again), and on a GPU the
same crashes and hits, ``f`` within the agreement tolerance.
"""

import json
from pathlib import Path

import numpy as np
import pytest
import torch

from avrisk.assembly import ScenarioSimulator, SimulationObjective
from avrisk.scenario import load_spec

FIXTURE = Path(__file__).with_name("highway_idm_near_threshold.json")
#: Thresholds [s] whose hits must agree across devices.
GAMMAS = (0.1, 0.3, 0.5)
#: Largest |f_cpu - f_gpu| [s] accepted (benchmarks/sim_throughput.py's).
F_TOLERANCE = 1e-3


def _recorded() -> dict:
    return json.loads(FIXTURE.read_text())


def _replay(device: str) -> tuple[np.ndarray, np.ndarray]:
    data = _recorded()
    sim = ScenarioSimulator(load_spec(data["scenario"]), device=device)
    with torch.no_grad():
        res = sim.rollout(np.array(data["x"]), np.array(data["seeds"], dtype=np.int64))
    return res.f.cpu().numpy().astype(np.float64), res.crash.cpu().numpy()


def test_the_recorded_rows_are_this_scenario_s():
    data = _recorded()
    definition = SimulationObjective(load_spec(data["scenario"])).definition()
    assert definition == data["defines_p"], (
        "highway_idm changed: compute its reference again and rewrite the fixture "
        "(benchmarks/device_agreement.py fixture)"
    )
    assert len(data["x"]) >= 32 and min(data["f"]) == 0.0 < max(data["f"])


def test_near_threshold_rollouts_replay_bit_for_bit_on_the_cpu():
    data = _recorded()
    f, crash = _replay("cpu")
    np.testing.assert_array_equal(f, np.array(data["f"]))
    np.testing.assert_array_equal(crash, np.array(data["crash"], dtype=bool))


@pytest.mark.gpu
@pytest.mark.skipif(
    not torch.cuda.is_available(), reason="no CUDA device present (CPU-only torch)"
)
def test_near_threshold_rollouts_agree_on_cpu_and_gpu():
    f_cpu, crash_cpu = _replay("cpu")
    f_gpu, crash_gpu = _replay("cuda")
    np.testing.assert_array_equal(crash_gpu, crash_cpu)
    for g in GAMMAS:
        np.testing.assert_array_equal(f_gpu <= g, f_cpu <= g, err_msg=f"f <= {g}")
    np.testing.assert_allclose(f_gpu, f_cpu, rtol=0, atol=F_TOLERANCE)
