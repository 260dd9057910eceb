"""The reference AV served through the API: the address it may bind, what it serves."""

import pytest

import avrisk.agents.external.server as server_module
from avrisk.api.ego_server import BindError, NotLoopbackError, serve_reference_ego


@pytest.fixture
def served(monkeypatch):
    """What ``serve`` was asked to serve, instead of binding a socket."""
    calls = []

    def serve(server, address, *, ready=None):
        calls.append((server, address))
        if ready is not None:
            ready(address)

    monkeypatch.setattr(server_module, "serve", serve)
    return calls


def test_the_reference_controller_is_served_at_the_address_with_its_settings(served):
    bound = []
    serve_reference_ego("ipc:///tmp/av.sock", speed=25.0, noise=0.3, ready=bound.append)
    ((server, address),) = served
    assert address == "ipc:///tmp/av.sock" and bound == [address]
    assert isinstance(server.controller, server_module.AccController)
    assert (server.controller.speed, server.controller.noise) == (25.0, 0.3)


def test_an_address_beyond_this_machine_needs_remote(served):
    with pytest.raises(NotLoopbackError, match="10.0.0.7"):
        serve_reference_ego("tcp://10.0.0.7:5555")
    assert served == []
    serve_reference_ego("tcp://10.0.0.7:5555", remote=True)
    assert [address for _, address in served] == ["tcp://10.0.0.7:5555"]


def test_an_address_zeromq_cannot_bind_is_one_clear_error(tmp_path):
    missing = f"ipc://{tmp_path}/no/such/folder/av.sock"
    with pytest.raises(BindError, match="cannot bind ipc://"):
        serve_reference_ego(missing)
