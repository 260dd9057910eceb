import numpy as np
import pytest
import torch

from avrisk.agents.drivers import DriverNet, LearnedEgoPolicy
from avrisk.agents.vision import IMAGE_SHAPE, PilotNet, PilotNetEgo
from avrisk.assembly.parts import full_float32_on_gpus
from avrisk.render import CameraModel, RayCastCamera
from avrisk.safety import MinTTC
from avrisk.sim import Road, SimConfig, Simulator, VehicleState
from avrisk.sim.interfaces import Action


@pytest.fixture(scope="module")
def net():
    torch.manual_seed(0)
    return PilotNet(steer_mean=0.01, steer_scale=0.02).eval()


def images(n, seed=0):
    g = torch.Generator().manual_seed(seed)
    return torch.rand(n, *IMAGE_SHAPE, generator=g)


def test_pilotnet_has_the_published_layers_and_sizes(net):
    convs = [
        (c.in_channels, c.out_channels, c.kernel_size, c.stride) for c in net.convs
    ]
    assert convs == [
        (3, 24, (5, 5), (2, 2)),
        (24, 36, (5, 5), (2, 2)),
        (36, 48, (5, 5), (2, 2)),
        (48, 64, (3, 3), (1, 1)),
        (64, 64, (3, 3), (1, 1)),
    ]
    assert [d.out_features for d in net.dense] == [1164, 100, 50, 10, 1]
    assert net.dense[0].in_features == 64 * 1 * 18


def test_steering_is_the_output_in_radians(net):
    x = images(3)
    with torch.no_grad():
        assert torch.allclose(net.steer(x), 0.01 + 0.02 * net(x), atol=1e-7)


def test_an_images_steering_is_bit_identical_alone_and_anywhere_in_a_batch(net):
    x = images(45)
    with torch.no_grad():
        whole = net.steer(x)
        for i in (0, 17, 44):
            assert torch.equal(net.steer(x[i : i + 1])[0], whole[i])
        perm = torch.randperm(45, generator=torch.Generator().manual_seed(1))
        assert torch.equal(net.steer(x[perm]), whole[perm])


@pytest.mark.gpu
@pytest.mark.skipif(
    not torch.cuda.is_available(), reason="no CUDA device present (CPU-only torch)"
)
def test_on_a_gpu_steering_is_batch_independent_and_the_cpus_within_rounding(net):
    # 600 images: one full inner batch of the GPU's and a padded second one.
    full_float32_on_gpus()  # as the simulator does on a GPU
    x = images(600)
    gpu = PilotNet(steer_mean=0.01, steer_scale=0.02).eval()
    gpu.load_state_dict(net.state_dict())
    gpu = gpu.to("cuda")
    with torch.no_grad():
        whole = gpu.steer(x.to("cuda"))
        for i in (0, 511, 599):
            assert torch.equal(gpu.steer(x[i : i + 1].to("cuda"))[0], whole[i])
        perm = torch.randperm(600, generator=torch.Generator().manual_seed(1))
        assert torch.equal(gpu.steer(x[perm].to("cuda")), whole[perm.to("cuda")])
        torch.testing.assert_close(whole.cpu(), net.steer(x), rtol=0, atol=1e-5)


def test_pilotnet_refuses_images_of_another_size(net):
    with pytest.raises(ValueError, match="width 200, height 66"):
        net.steer(torch.zeros(1, 3, 60, 200))


def test_saved_weights_load_back_as_float16_rounded_float32(net, tmp_path):
    path = tmp_path / "p.npz"
    net.save(path)
    with np.load(path, allow_pickle=False) as data:
        assert data["convs.0.weight"].dtype == np.float16
        assert data["steer_scale"].dtype == np.float32
    back = PilotNet.load(path)
    w = net.convs[0].weight.detach()
    assert torch.equal(back.convs[0].weight, w.half().float())
    assert back.steer_scale.item() == pytest.approx(0.02)
    np.savez(tmp_path / "bad.npz", x=np.zeros(2))
    with pytest.raises(ValueError, match="not PilotNet weights"):
        PilotNet.load(tmp_path / "bad.npz")


def two_cars(b=3):
    rows = [[0.0, 5.55, 0.0, 20.0, 4.8, 1.9], [40.0, 5.55, 0.0, 18.0, 4.8, 1.9]]
    return VehicleState.from_rows([rows] * b)


class _Cruise:
    controlled = torch.tensor([False, True])
    reads_lidar, noise = False, None

    def init(self, obs, params):
        return None

    def act(self, obs, state, noise):
        zero = torch.zeros_like(obs.state.x)
        return Action(zero, zero), None


def test_the_vision_ego_steers_from_the_camera_and_throttles_from_lidar(net):
    road = Road(n_lanes=3)
    driver_net = DriverNet()
    ego = PilotNetEgo(net, LearnedEgoPolicy(driver_net, 2))
    sim = Simulator(
        road, SimConfig(horizon=0.3), measure=MinTTC(), camera=RayCastCamera(road)
    )
    seen = []

    class Spy(PilotNetEgo):
        def act(self, obs, state, noise):
            seen.append(obs.camera)
            action, state = super().act(obs, state, noise)
            lidar, _ = self.throttle.act(obs, state, None)
            assert torch.equal(action.accel, lidar.accel)
            assert torch.equal(action.steer[:, 0], self.net.steer(obs.camera.rgb))
            return action, state

    spy = Spy(net, ego.throttle)
    res = sim.run(two_cars(), [_Cruise(), spy], torch.arange(3))
    assert res.steps.tolist() == [3, 3, 3]
    assert len(seen) == 3 and tuple(seen[0].rgb.shape) == (3, 3, 66, 200)


def test_a_camera_is_rendered_only_for_an_actor_that_reads_it():
    road = Road(n_lanes=3)
    calls = []

    class CountingCamera(RayCastCamera):
        def __call__(self, state):
            calls.append(state.batch_size)
            return super().__call__(state)

    camera = CountingCamera(road, CameraModel(width=8, height=4))
    sim = Simulator(road, SimConfig(horizon=0.2), measure=MinTTC(), camera=camera)

    class Blind(_Cruise):
        controlled = torch.tensor([True, True])

    class Looking(Blind):
        reads_camera = True

        def act(self, obs, state, noise):
            assert obs.camera is not None and obs.camera.width == 8
            return super().act(obs, state, noise)

    sim.run(two_cars(), [Blind()], torch.arange(3))
    assert calls == []
    sim.run(two_cars(), [Looking()], torch.arange(3))
    assert calls == [3, 3, 3]  # t = 0 and two steps
    no_camera = Simulator(road, SimConfig(horizon=0.2), measure=MinTTC())
    with pytest.raises(ValueError, match="Looking reads the camera"):
        no_camera.run(two_cars(), [Looking()], torch.arange(3))
