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
