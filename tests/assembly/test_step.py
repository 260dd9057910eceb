"""The functional simulation step of both bundled scenarios: compile, ops, grads."""

import shutil

import numpy as np
import pytest
import torch

from avrisk.agents.drivers.driver import LearnedState
from avrisk.assembly import ScenarioSimulator, base_distribution
from avrisk.rare.problem import chunk_rng, sample_seeds
from avrisk.scenario import load_spec
from avrisk.tensors.opcount import OpCounter

SCENARIOS = ("highway_idm", "highway_default")

#: ATen operations per eager step at small batches (one lidar slice), as
#: benchmarks/step_profile.py reports them and BENCHMARKS.md records them; the
#: bound leaves 15% room. A Python loop over vehicles multiplies the count by
#: about A = 6.
OPS_PER_STEP = {"highway_idm": 986, "highway_default": 904}


def started(scenario, batch, horizon=1.0):
    """``(carry, step)`` of a batch of ``scenario`` (short horizon)."""
    spec = load_spec(scenario)
    sim = spec.simulation.model_copy(update={"horizon": horizon})
    ss = ScenarioSimulator(spec.model_copy(update={"simulation": sim}))
    x = base_distribution(ss.spec).sample(batch, chunk_rng(0, 0, 0))
    return ss.start(x, sample_seeds(0, 0, np.arange(batch)))


def unroll(step, carry, n_steps, index=lambda t: t):
    """``n_steps`` steps; the carries after each."""
    carries = []
    for t in range(n_steps):
        carry, _ = step(carry, index(t))
        carries.append(carry)
    return carries


def leaves(carry):
    return [t for t in torch.utils._pytree.tree_leaves(carry) if torch.is_tensor(t)]


@pytest.mark.parametrize("scenario", SCENARIOS)
def test_a_step_dispatches_a_bounded_number_of_ops_whatever_the_batch(scenario):
    counts = []
    for batch in (16, 64):
        carry, step = started(scenario, batch)
        with torch.no_grad(), OpCounter() as ops:
            step(carry, 0)
        counts.append(ops.total)
        assert ops.counts["aten._local_scalar_dense.default"] == 0  # no host sync
    assert counts[0] == counts[1]
    assert counts[0] <= 1.15 * OPS_PER_STEP[scenario]


@pytest.mark.parametrize("scenario", SCENARIOS)
def test_the_carry_keeps_its_layout_so_one_compiled_graph_serves_every_step(scenario):
    carry, step = started(scenario, 16)
    with torch.no_grad():
        carries = [carry, *unroll(step, carry, 2)]

    def layout(c):
        return [(t.shape, t.stride(), t.dtype) for t in leaves(c)]

    assert layout(carries[0]) == layout(carries[1]) == layout(carries[2])


def test_the_step_is_the_loop_of_run():
    spec = load_spec("highway_default")
    carry, step = started("highway_default", 16, horizon=spec.simulation.dt * 5)
    with torch.no_grad():
        last = unroll(step, carry, 5)[-1]
    ss = ScenarioSimulator(
        spec.model_copy(
            update={"simulation": spec.simulation.model_copy(update={"horizon": 0.5})}
        )
    )
    x = base_distribution(spec).sample(16, chunk_rng(0, 0, 0))
    res = ss.rollout(x, sample_seeds(0, 0, np.arange(16)))
    assert torch.equal(res.steps, last.steps) and torch.equal(res.crash, last.crash)
    f = ss.simulator.measure.finalize(last.measure)
    expected = torch.where(last.status == 0, f, torch.nan)
    torch.testing.assert_close(res.f, expected, rtol=0, atol=0, equal_nan=True)


def test_gradients_flow_from_the_rollout_to_the_drivers_xi():
    carry, step = started("highway_default", 8, horizon=1.0)
    driver_state = carry.actors[0]
    assert isinstance(driver_state, LearnedState)
    xi = driver_state.xi.clone().requires_grad_()
    carry = carry._replace(actors=(driver_state._replace(xi=xi), *carry.actors[1:]))
    last = unroll(step, carry, 10)[-1]
    loss = last.state.x.sum() + last.state.y.sum()
    (grad,) = torch.autograd.grad(loss, xi)
    assert torch.isfinite(grad).all() and grad.abs().sum() > 0


@pytest.mark.slow
@pytest.mark.skipif(
    not any(shutil.which(c) for c in ("g++", "c++", "clang++")),
    reason="torch.compile needs a C++ compiler",
)
@pytest.mark.parametrize("scenario", SCENARIOS)
def test_the_step_compiles_to_one_graph_with_bit_identical_results(scenario):
    carry, step = started(scenario, 8)
    with torch.no_grad():
        explained = torch._dynamo.explain(step)(carry, torch.tensor(0))
        assert (explained.graph_count, explained.graph_break_count) == (1, 0)
        compiled = torch.compile(step, fullgraph=True)
        eager = unroll(step, carry, 4)
        fused = unroll(compiled, carry, 4, index=torch.tensor)
    for a, b in zip(eager, fused, strict=True):
        for x, y in zip(leaves(a), leaves(b), strict=True):
            assert torch.equal(x, y)


@pytest.mark.gpu
@pytest.mark.skipif(
    not torch.cuda.is_available(), reason="no CUDA device present (CPU-only torch)"
)
@pytest.mark.parametrize("scenario", SCENARIOS)
def test_cpu_and_gpu_rollouts_agree(scenario):
    spec = load_spec(scenario)
    results = []
    for device in ("cpu", "cuda"):
        ss = ScenarioSimulator(spec, device=device)
        x = base_distribution(spec).sample(256, chunk_rng(0, 0, 0))
        res = ss.rollout(x, sample_seeds(0, 0, np.arange(256)))
        results.append((res.f.cpu(), res.crash.cpu()))
    (f_cpu, crash_cpu), (f_gpu, crash_gpu) = results
    # Elementwise work is bit-identical; the matrix products may round
    # differently on a GPU, so f agrees to a tolerance (benchmarks/sim_throughput.py).
    assert torch.equal(crash_cpu, crash_gpu)
    torch.testing.assert_close(f_gpu, f_cpu, rtol=0, atol=1e-3, equal_nan=True)


@pytest.mark.parametrize("scenario", SCENARIOS)
def test_restarted_rollouts_finish_as_they_would_alone(scenario):
    """Rows restarted mid-batch, stepped with a step index per row: as run alone.

    highway_default samples its drivers' actions here, so the noise (drawn by
    step index) and its AR(1) start are per row too.
    """
    spec = load_spec(scenario)
    sim = spec.simulation.model_copy(update={"horizon": 1.0})
    spec = spec.model_copy(update={"simulation": sim})
    if spec.learned_drivers is not None:
        drivers = spec.learned_drivers.model_copy(update={"actions": "sampled"})
        spec = spec.model_copy(update={"learned_drivers": drivers})
    ss, p0 = ScenarioSimulator(spec), base_distribution(spec)
    n_steps = ss.config.n_steps
    x, seeds = p0.sample(6, chunk_rng(0, 0, 0)), sample_seeds(0, 0, np.arange(6))
    carry, step = ss.start(x, seeds)
    t = torch.zeros(6, dtype=torch.int64)
    with torch.no_grad():
        for _ in range(4):
            carry, _ = step(carry, t)
            t += 1
        rows = torch.tensor([False, True, False, False, True, False])
        x_new, seeds_new = p0.sample(2, chunk_rng(0, 0, 1)), sample_seeds(0, 1, [0, 1])
        carry = ss.restart(carry, rows, x_new, seeds_new)
        x[rows.numpy()], seeds[rows.numpy()], t[rows] = x_new, seeds_new, 0
        finished = {}
        while len(finished) < 6:
            carry, _ = step(carry, t, seeds=torch.as_tensor(seeds))
            t += 1
            f = ss.simulator.measure.finalize(carry.measure)
            for b in torch.nonzero(t == n_steps).flatten().tolist():
                finished[b] = (carry.state.x[b], f[b], carry.steps[b], carry.crash[b])
    assert (t > n_steps).any()  # the rows were out of step
    alone = ss.rollout(x, seeds, record_trace=True)
    for b, (pos, f_b, steps, crash) in finished.items():
        assert torch.equal(pos, alone.trace.x[b, -1]) and torch.equal(f_b, alone.f[b])
        assert int(steps) == int(alone.steps[b]) and bool(crash) == bool(alone.crash[b])
