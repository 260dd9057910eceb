import math

import pytest
import torch

from avrisk.agents import ConstantPolicy, IDMDriver, IDMParams, IDMPolicy, ego_only
from avrisk.safety import MinBoxTTC, MinTTC
from avrisk.sim import Contact, Road, SimConfig, Simulator, Status, VehicleState
from avrisk.sim.interfaces import Action, reads_lidar

F64 = torch.float64
SIZE = [4.0, 2.0]
ROAD = Road(n_lanes=3, lane_width=4.0)


def seeds(n):
    return torch.arange(n, dtype=torch.int64)


def simulator(config=None, *, dtype=torch.float32, measure=None, **kw):
    """A simulator on ROAD with the ray TTC (360 rays) unless told otherwise."""
    config = SimConfig() if config is None else config
    measure = MinTTC(dtype=dtype) if measure is None else measure
    return Simulator(ROAD, config, measure=measure, dtype=dtype, **kw)


def idm_rollout(sim, state, params, seeds, *, ego=None, record_trace=False):
    """Every vehicle IDM+MOBIL, the ego replaced by ``ego`` if given."""
    actors = [IDMDriver(params, ROAD)] + ([] if ego is None else [ego])
    return sim.run(state, actors, seeds, record_trace=record_trace)


def test_a_cruising_ego_rear_ends_a_slower_car_at_the_step_the_boxes_first_overlap():
    # Bumper gap 26 m closing at 10 m/s, 1 m per step: touching (not a crash)
    # after 26 steps, overlapping after 27.
    sim = simulator(dtype=F64)
    state = VehicleState.from_rows(
        [[0.0, 2.0, 0.0, 25.0, *SIZE], [30.0, 2.0, 0.0, 15.0, *SIZE]], dtype=F64
    )
    params = IDMParams.full(state.shape, dtype=F64, desired_speed=15.0)
    res = idm_rollout(
        sim, state, params, seeds(1), ego=ConstantPolicy(ego_only(2)), record_trace=True
    )
    assert res.crash.tolist() == [True]
    assert res.steps.tolist() == [27]
    assert res.collision_with.tolist() == [1]
    assert res.contact.tolist() == [Contact.REAR_END]
    assert res.status.tolist() == [Status.OK]
    # At the crash step the ego centre is 1 m from the lead's rear, closing at 10 m/s.
    assert res.f.item() == pytest.approx(0.1, rel=1e-9)
    # The rollout stopped: later frames repeat the crash frame and are not alive.
    tr = res.trace
    assert tr.alive[0].tolist() == [True] * 28 + [False] * 73
    assert torch.equal(tr.x[0, 27:], tr.x[0, 27:28].expand(74, -1))
    assert tr.ttc[0, 28:].eq(math.inf).all()
    assert not res.offroad.item() and not res.reversing.item()


def test_a_rollout_that_starts_in_a_crash_stops_at_step_zero():
    sim = simulator()
    state = VehicleState.from_rows(
        [[0.0, 2.0, 0.0, 25.0, *SIZE], [3.0, 2.5, 0.0, 15.0, *SIZE]]
    )
    res = idm_rollout(sim, state, IDMParams.full(state.shape), seeds(1))
    assert res.crash.tolist() == [True] and res.steps.tolist() == [0]
    assert res.contact.tolist() == [Contact.REAR_END]
    assert res.f.item() == pytest.approx(0.1, rel=1e-6)  # 1 m at 10 m/s


def test_steering_off_the_road_is_flagged_without_stopping_the_rollout():
    sim = simulator(SimConfig(horizon=3.0))
    state = VehicleState.from_rows([[0.0, 10.0, 0.0, 20.0, *SIZE]])
    res = sim.run(state, [ConstantPolicy(ego_only(1), steer=0.1)], seeds(1))
    assert res.offroad.tolist() == [True]
    assert not res.crash.item() and res.steps.item() == 30


def test_braking_through_standstill_is_flagged_as_reversing():
    sim = simulator(SimConfig(horizon=2.0))
    state = VehicleState.from_rows([[0.0, 2.0, 0.0, 3.0, *SIZE]])
    params = IDMParams.full(state.shape)
    assert not idm_rollout(sim, state, params, seeds(1)).reversing.item()
    ego = ConstantPolicy(ego_only(1), accel=-4.0)
    res = idm_rollout(sim, state, params, seeds(1), ego=ego)
    assert res.reversing.tolist() == [True]


def test_the_contact_mechanism_of_a_crash_is_rear_end_from_behind_or_side():
    road = Road(n_lanes=3, lane_width=3.7)
    sim = Simulator(road, SimConfig(horizon=5.0), measure=MinTTC(dtype=F64), dtype=F64)
    car = [4.8, 1.9]
    scenes = [
        # The ego closes on a slower car ahead in its lane.
        [[0.0, 1.85, 0.0, 25.0, *car], [30.0, 1.85, 0.0, 15.0, *car]],
        # A faster car closes on the ego from behind in its lane.
        [[0.0, 1.85, 0.0, 15.0, *car], [-30.0, 1.85, 0.0, 25.0, *car]],
        # The ego drifts left into a car driving alongside in the next lane.
        [[0.0, 1.85, 0.05, 20.0, *car], [1.0, 5.55, 0.0, 20.0, *car]],
        # Nobody meets.
        [[0.0, 1.85, 0.0, 20.0, *car], [60.0, 5.55, 0.0, 20.0, *car]],
    ]
    state = VehicleState.from_rows(scenes, dtype=F64)
    res = sim.run(state, [ConstantPolicy(torch.tensor([True, True]))], seeds(4))
    assert res.crash.tolist() == [True, True, True, False]
    assert res.collision_with.tolist() == [1, 1, 1, -1]
    assert res.contact.tolist() == [
        Contact.REAR_END, Contact.FROM_BEHIND, Contact.SIDE, Contact.NONE
    ]  # fmt: skip
    assert res.contact.dtype == torch.int8 and res.status.dtype == torch.int8


def test_a_free_road_gives_infinite_ttc_and_the_full_horizon():
    sim = simulator(SimConfig(horizon=1.0))
    state = VehicleState.from_rows(
        [[0.0, 2.0, 0.0, 20.0, *SIZE], [50.0, 10.0, 0.0, 25.0, *SIZE]]
    )
    params = IDMParams.full(state.shape)
    res = idm_rollout(sim, state, params, seeds(1), record_trace=True)
    assert res.f.tolist() == [math.inf]
    assert res.steps.tolist() == [10] and res.collision_with.tolist() == [-1]
    assert res.contact.tolist() == [Contact.NONE]
    assert res.trace.x.shape == (1, 11, 2) and res.trace.alive.all()


def traffic(n, seed=0):
    """n varied scenes of six vehicles, some of them dense enough to crash."""
    g = torch.Generator().manual_seed(seed)
    lanes = torch.tensor([1, 1, 2, 0, 1, 2])
    offsets = torch.tensor([0.0, 18.0, 6.0, 8.0, -16.0, 25.0])
    x = offsets + 8.0 * torch.rand(n, 6, generator=g)
    y = (lanes + 0.5) * 4.0 + 0.5 * torch.rand(n, 6, generator=g) - 0.25
    heading = torch.deg2rad(7.2 * torch.rand(n, 6, generator=g) - 3.6)
    speed = 10.0 + 15.0 * torch.rand(n, 6, generator=g)
    length = torch.tensor([4.8, 4.8, 4.8, 4.8, 4.8, 12.0]).expand(n, 6).contiguous()
    width = torch.tensor([1.9, 1.9, 1.9, 1.9, 1.9, 2.5]).expand(n, 6).contiguous()
    if n >= 6:
        # Scene 3: a slow car cuts in 2 m ahead of the ego, too close to brake.
        x[3, 1], y[3, 1], speed[3, 0], speed[3, 1] = x[3, 0] + 6.8, y[3, 0], 25.0, 5.0
        # Scene 5: starts with a car overlapping the ego.
        x[5, 2], y[5, 2] = x[5, 0] + 3.0, y[5, 0] + 1.0
    state = VehicleState(x, y, heading, speed, length, width)
    params = IDMParams.full((n, 6))
    params = IDMParams(
        desired_speed=15.0 + 15.0 * torch.rand(n, 6, generator=g),
        time_headway=0.5 + 1.5 * torch.rand(n, 6, generator=g),
        min_gap=params.min_gap,
        max_accel=params.max_accel,
        comfort_decel=params.comfort_decel,
        politeness=torch.rand(n, 6, generator=g),
        lane_change_threshold=0.3 * torch.rand(n, 6, generator=g),
    )
    return state, params


RESULTS = (
    "f", "crash", "offroad", "reversing", "steps", "status", "collision_with", "contact"
)  # fmt: skip


def assert_same(a, b):
    for name in RESULTS:
        assert torch.equal(getattr(a, name), getattr(b, name)), name
    for name in ("x", "y", "heading", "speed", "alive", "ttc"):
        assert torch.equal(getattr(a.trace, name), getattr(b.trace, name)), name


@pytest.fixture(scope="module")
def batch_of_seven():
    sim = simulator(SimConfig(horizon=3.0))
    state, params = traffic(7)
    res = idm_rollout(sim, state, params, seeds(7), record_trace=True)
    return sim, state, params, res


def test_the_test_traffic_exercises_crashes_lane_changes_and_near_misses(
    batch_of_seven,
):
    _, state, _, res = batch_of_seven
    assert res.crash[3] and res.crash[5] and res.steps[5] == 0 and not res.crash.all()
    lanes_at_end = ROAD.lane_index(res.trace.y[:, -1])
    assert (lanes_at_end != ROAD.lane_index(state.y)).any()
    assert torch.isfinite(res.f).all() and (res.status == Status.OK).all()
    assert res.contact[3] == Contact.REAR_END
    assert torch.equal(res.contact != Contact.NONE, res.crash)


def test_a_rollout_alone_gives_bit_identical_results_to_the_same_rollout_in_a_batch(
    batch_of_seven,
):
    sim, state, params, res = batch_of_seven
    for b in range(7):
        alone = idm_rollout(
            sim, state[b : b + 1], params[b : b + 1], seeds(7)[b : b + 1],
            record_trace=True,
        )  # fmt: skip
        assert_same(alone, _select(res, [b]))


def test_permuting_the_batch_permutes_the_results_bit_for_bit(batch_of_seven):
    sim, state, params, res = batch_of_seven
    perm = torch.tensor([3, 6, 0, 5, 1, 4, 2])
    shuffled = idm_rollout(
        sim, state[perm], params[perm], seeds(7)[perm], record_trace=True
    )
    assert_same(shuffled, _select(res, perm))


def test_a_larger_batch_gives_the_same_results_for_the_shared_rollouts(batch_of_seven):
    sim, state, params, res = batch_of_seven
    state2, params2 = traffic(5, seed=1)
    both = idm_rollout(
        sim, VehicleState.cat([state, state2]), IDMParams.cat([params, params2]),
        seeds(12), record_trace=True,
    )  # fmt: skip
    assert_same(_select(both, list(range(7))), res)


def _select(res, index):
    index = torch.as_tensor(index)
    tr = res.trace
    return type(res)(
        **{name: getattr(res, name)[index] for name in RESULTS},
        trace=type(tr)(
            *(
                getattr(tr, k)[index]
                for k in ("x", "y", "heading", "speed", "alive", "ttc")
            )
        ),
    )


def test_the_idm_ego_policy_drives_exactly_like_the_default_ego(batch_of_seven):
    sim, state, params, res = batch_of_seven
    ego = IDMPolicy(params, ROAD)
    assert ego.controlled.tolist() == [True] + [False] * 5
    with_policy = idm_rollout(sim, state, params, seeds(7), ego=ego, record_trace=True)
    assert_same(with_policy, res)


def test_actors_set_the_vehicles_they_control_later_ones_overriding():
    sim = simulator(SimConfig(horizon=0.5), dtype=F64)
    rows = [[0.0, 2.0, 0.0, 20.0, *SIZE], [40.0, 6.0, 0.0, 20.0, *SIZE]]
    rows += [[80.0, 10.0, 0.0, 20.0, *SIZE]]
    state = VehicleState.from_rows(rows, dtype=F64)
    first = ConstantPolicy(torch.tensor([True, True, False]), accel=1.0)
    second = ConstantPolicy(torch.tensor([False, True, True]), accel=-2.0)
    res = sim.run(state, [first, second], seeds(1), record_trace=True)
    expected = torch.tensor([[20.5, 19.0, 19.0]], dtype=F64)
    torch.testing.assert_close(res.trace.speed[:, -1], expected)
    swapped = sim.run(state, [second, first], seeds(1), record_trace=True)
    expected = torch.tensor([[20.5, 20.5, 19.0]], dtype=F64)
    torch.testing.assert_close(swapped.trace.speed[:, -1], expected)


def test_a_vehicle_that_no_actor_controls_or_a_bad_mask_is_refused():
    sim = simulator(SimConfig(horizon=0.5))
    state, _ = traffic(2)
    half = ConstantPolicy(torch.tensor([True, True, True, False, False, True]))
    with pytest.raises(
        ValueError, match=r"vehicles \[3, 4\] are controlled by no actor"
    ):
        sim.run(state, [half], seeds(2))
    with pytest.raises(ValueError, match="controlled must be a bool tensor of shape"):
        sim.run(state, [ConstantPolicy(torch.ones(6))], seeds(2))
    with pytest.raises(ValueError, match="at least one actor"):
        sim.run(state, [], seeds(2))


class _FailsFor:
    """IDM+MOBIL for every vehicle, but NaN actions in some rollouts from a step."""

    reads_lidar, noise = False, None

    def __init__(self, params, rollouts, from_step):
        self.inner = IDMDriver(params, ROAD)
        self.controlled = self.inner.controlled
        self.rollouts, self.from_step = torch.tensor(rollouts), from_step

    def init(self, obs, params):
        return self.inner.init(obs, params)

    def act(self, obs, state, noise):
        action, state = self.inner.act(obs, state, noise)
        fail = torch.zeros(obs.state.batch_size, dtype=torch.bool)
        if obs.step >= self.from_step:
            fail[self.rollouts] = True
        accel = torch.where(fail[:, None], math.nan, action.accel)
        return Action(accel=accel, steer=action.steer), state


def test_an_actor_that_fails_for_a_rollout_stops_only_that_one_with_status_and_nan_f(
    batch_of_seven,
):
    sim, state, params, res = batch_of_seven
    failing = _FailsFor(params, [1, 3, 5], from_step=4)
    out = sim.run(state, [failing], seeds(7), record_trace=True)
    failed = torch.tensor([False, True, False, False, False, False, False])
    # Rollout 3 crashes at step 1 and rollout 5 starts crashed: they stop first.
    assert res.steps[3] < 4 and res.steps[5] == 0
    assert out.status.tolist() == [int(f) for f in failed]
    assert torch.isnan(out.f[1]) and out.steps[1] == 4 and not out.crash[1]
    assert not out.trace.alive[1, 5:].any() and out.trace.alive[1, :5].all()
    ok = ~failed
    assert_same(
        _select(out, torch.nonzero(ok).flatten()), _select(res, ok.nonzero().flatten())
    )


class _LidarSpy:
    """Wraps an actor without declaring ``reads_lidar``; notes obs.lidar."""

    noise = None

    def __init__(self, inner):
        self.inner, self.saw_lidar = inner, []
        self.controlled = inner.controlled

    def init(self, obs, params):
        return self.inner.init(obs, params)

    def act(self, obs, state, noise):
        self.saw_lidar.append(obs.lidar is not None)
        return self.inner.act(obs, state, noise)


def test_lidar_is_scanned_only_for_models_that_read_it_and_changes_nothing_else(
    batch_of_seven,
):
    sim, state, params, res = batch_of_seven
    idm = IDMDriver(params, ROAD)
    assert not reads_lidar(idm) and not reads_lidar(ConstantPolicy(ego_only(6)))
    spy_of_idm = _LidarSpy(idm)  # undeclared: assumed to read the lidar
    scanned = sim.run(state, [spy_of_idm], seeds(7), record_trace=True)
    assert all(spy_of_idm.saw_lidar)
    assert_same(scanned, res)
    # An actor that declares it never reads lidar gets none, whatever wraps it.
    spy_of_idm.reads_lidar = False
    spy_of_idm.saw_lidar.clear()
    sim.run(state, [spy_of_idm], seeds(7))
    assert spy_of_idm.saw_lidar and not any(spy_of_idm.saw_lidar)
    # Every actor counts: an undeclared ego brings the scan back.
    ego = _LidarSpy(IDMPolicy(params, ROAD))
    with_ego = sim.run(state, [idm, ego], seeds(7), record_trace=True)
    assert all(ego.saw_lidar)
    assert_same(with_ego, res)


def test_trace_alive_marks_exactly_the_simulated_steps(batch_of_seven):
    _, _, _, res = batch_of_seven
    t = torch.arange(res.trace.alive.shape[1])
    assert torch.equal(res.trace.alive, t[None, :] <= res.steps[:, None])


def test_f_is_the_minimum_of_the_traced_ttc(batch_of_seven):
    _, _, _, res = batch_of_seven
    assert torch.equal(res.f, res.trace.ttc.amin(dim=1))


def test_observations_carry_lidar_and_lane_features_for_every_vehicle():
    sim = simulator(SimConfig(n_lidar_beams=8))
    state, _ = traffic(3)
    obs = sim.observe(state, seeds(3))
    assert obs.lidar.range.shape == (3, 6, 8)
    assert obs.lane.lane.tolist() == ROAD.lane_index(state.y).tolist()
    assert obs.collided.shape == (3, 6)
    assert simulator(SimConfig(n_lidar_beams=0)).observe(state, seeds(3)).lidar is None


def test_bad_inputs_are_rejected_with_a_message_that_names_them():
    sim = simulator(SimConfig(horizon=0.5))
    state, params = traffic(2)
    idm = IDMDriver(params, ROAD)
    with pytest.raises(ValueError, match="seeds"):
        sim.run(state, [idm], torch.zeros(2, dtype=torch.int32))
    with pytest.raises(ValueError, match="length"):
        sim.run(state.map(lambda t: t * 0), [idm], seeds(2))
    with pytest.raises(ValueError, match="one entry .* per actor"):
        sim.run(state, [idm], seeds(2), params=[None, None])
    with pytest.raises(ValueError, match=r"params\[0\] must have shape \(2, P\)"):
        sim.run(state, [idm], seeds(2), params=[torch.zeros(3, 4)])
    with pytest.raises(NotImplementedError, match="curvature"):
        Simulator(Road(curvature=0.01), measure=MinTTC())
    with pytest.raises(ValueError, match="dt"):
        SimConfig(dt=0.0)


def test_the_config_counts_steps_like_the_horizon_over_the_time_step():
    assert SimConfig().n_steps == 100
    assert SimConfig(dt=0.05, horizon=1.0).n_steps == 20
    assert SimConfig(dt=0.3, horizon=1.0).n_steps == 4


def _have_cxx():
    import shutil

    return any(shutil.which(c) for c in ("g++", "c++", "clang++"))


@pytest.mark.slow
@pytest.mark.skipif(not _have_cxx(), reason="torch.compile needs a C++ compiler")
def test_compiled_steps_give_bit_identical_results_to_eager_ones(batch_of_seven):
    _, state, params, res = batch_of_seven
    sim = simulator(SimConfig(horizon=3.0), compile=True)
    assert sim.compile
    assert_same(idm_rollout(sim, state, params, seeds(7), record_trace=True), res)
    perm = torch.tensor([6, 5, 4, 3, 2, 1, 0])
    shuffled = idm_rollout(
        sim, state[perm], params[perm], seeds(7)[perm], record_trace=True
    )
    assert_same(shuffled, _select(res, perm))


@pytest.mark.slow
@pytest.mark.skipif(not _have_cxx(), reason="torch.compile needs a C++ compiler")
def test_the_box_ttc_measure_compiles_to_bit_identical_results(batch_of_seven):
    _, state, params, _ = batch_of_seven
    config = SimConfig(horizon=3.0)
    eager = simulator(config, measure=MinBoxTTC())
    compiled = simulator(config, measure=MinBoxTTC(), compile=True)
    assert_same(
        idm_rollout(compiled, state, params, seeds(7), record_trace=True),
        idm_rollout(eager, state, params, seeds(7), record_trace=True),
    )


def test_the_environment_switches_compilation_on_unless_told_otherwise(monkeypatch):
    from avrisk.sim.config import COMPILE_ENV, compile_requested

    monkeypatch.setenv(COMPILE_ENV, "1")
    assert compile_requested(None) and not compile_requested(False)
    monkeypatch.setenv(COMPILE_ENV, "0")
    assert not compile_requested(None) and compile_requested(True)
    monkeypatch.delenv(COMPILE_ENV)
    assert not compile_requested(None)
    assert not simulator().compile
