"""The external-ego protocol's parsing: untrusted messages are checked."""

import msgpack
import numpy as np
import pytest

pytest.importorskip("msgpack")

from avrisk.agents.external import ExternalParams  # noqa: E402
from avrisk.agents.external.protocol import (  # noqa: E402
    ProtocolError,
    decode,
    encode,
    pack_array,
    unpack_array,
)
from avrisk.agents.external.server import AccController, EgoServer  # noqa: E402


def test_arrays_round_trip_little_endian():
    a = np.arange(6, dtype=">f4").reshape(2, 3)
    wire = pack_array(a)
    assert wire["dtype"] == "f4" and wire["data"][:4] == np.float32(0).tobytes()
    back = unpack_array(wire, "a", dtypes=("f4",), shape=(2, 3))
    assert np.array_equal(back, a)
    assert pack_array(np.array([True, False]))["dtype"] == "u1"


@pytest.mark.parametrize(
    ("wire", "message"),
    [
        ({"dtype": "f8", "shape": [3], "data": bytes(24)}, "dtype 'f8'"),
        ({"dtype": "f4", "shape": [3], "data": bytes(11)}, "not 3 f4 values"),
        ({"dtype": "f4", "shape": [True, 3], "data": bytes(12)}, "shape must be"),
        ({"dtype": "f4", "shape": [3]}, "not an array map"),
        ([1, 2, 3], "not an array map"),
    ],
)
def test_bad_arrays_are_refused_by_name(wire, message):
    with pytest.raises(ProtocolError, match=message):
        unpack_array(wire, "accel", dtypes=("f4",), shape=(3,))


def test_bad_messages_are_refused():
    with pytest.raises(ProtocolError, match="over the 10 limit"):
        decode(encode({"type": "step", "pad": bytes(20)}), 10)
    with pytest.raises(ProtocolError, match="extension type 5"):
        decode(msgpack.packb(msgpack.ExtType(5, b"x")), 100)
    with pytest.raises(ProtocolError, match="string 'type'"):
        decode(encode([1, 2]), 100)


def test_the_reference_server_answers_errors_not_exceptions():
    server = EgoServer(AccController())
    reply = decode(server.handle(encode({"type": "step", "episode": 1})), 10**6)
    assert reply == {"type": "error", "message": "step for episode 1, not reset"}
    reply = decode(server.handle(b"\xc1"), 10**6)
    assert reply["type"] == "error"
    reply = decode(server.handle(encode({"type": "hello", "protocol": 2})), 10**6)
    assert "speaks 1" in reply["message"]


def test_addresses_stay_on_this_machine_unless_allowed():
    assert ExternalParams().address == "tcp://127.0.0.1:5555"
    with pytest.raises(ValueError, match="allow_remote"):
        ExternalParams(address="tcp://example.com:5555")
    ExternalParams(address="tcp://example.com:5555", allow_remote=True)


def test_the_protocol_page_describes_the_handshake_avrisk_sends():
    """docs/ego-protocol.md's observation table and dtype codes are the code's."""
    import re
    from pathlib import Path

    import torch

    from avrisk.agents.external.client import _REPLY_OVERHEAD
    from avrisk.agents.external.protocol import DTYPES, PROTOCOL_VERSION
    from avrisk.agents.external.spaces import hello_message, observation_arrays
    from avrisk.assembly import ScenarioSimulator, base_distribution, initial_state
    from avrisk.scenario import ScenarioParams, load_spec

    page = (Path(__file__).parents[2] / "docs" / "ego-protocol.md").read_text()
    sim = ScenarioSimulator(load_spec("highway_idm"))
    x = base_distribution(sim.spec).sample(2, np.random.default_rng(0))
    state = initial_state(ScenarioParams.from_flat(x, sim.layout), sim.spec)
    obs = sim.simulator.observe(state, torch.zeros(2, dtype=torch.int64))
    hello = hello_message(observation_arrays(obs), obs.dt)
    n_beams = sim.config.n_lidar_beams
    documented = {}
    for names, dtype, shape, unit in re.findall(
        r"^\| (`[^|]+`) \| (\w+) \| \[(R?)\] \| ([^|]+?) \|", page, flags=re.M
    ):
        for name in re.findall(r"`(\w+)`", names):
            documented[name] = {
                "dtype": dtype,
                "shape": [n_beams] if shape else [],
                "unit": unit,
            }
    assert documented == hello["observation"]
    assert f"# The external-ego protocol, version {PROTOCOL_VERSION}" in page
    codes = set(re.findall(r'`"(\w\d)"` \w', page.split("## Arrays")[1]))
    assert codes == set(DTYPES)
    assert f"{_REPLY_OVERHEAD // 1024} KiB + 32 bytes per rollout" in page


def test_the_protocol_page_tables_the_params_and_the_action_limits():
    """Each param of ExternalParams with its default; the simulator's clip limits."""
    import re
    from pathlib import Path

    import yaml

    from avrisk.sim.config import SimConfig

    page = (Path(__file__).parents[2] / "docs" / "ego-protocol.md").read_text()
    section = page.split("## The scenario's params")[1].split("\n## ")[0]
    rows = re.findall(r"^\| `(\w+)` \| `([^`]+)`", section, flags=re.M)
    assert {name: yaml.safe_load(default) for name, default in rows} == {
        name: field.default for name, field in ExternalParams.model_fields.items()
    }
    limits = SimConfig()
    accel = f"`accel` to [{limits.accel_min:g}, {limits.accel_max:g}] m/s^2"
    steer = f"`steer` to [{-limits.max_steer:g}, {limits.max_steer:g}] rad"
    text = " ".join(page.split())
    assert accel in text and steer in text
