"""Backends by name: a new one is one module (``tests/user_backend.py``), run like
the bundled ones."""

import copy
import importlib
import sys

import pytest

import avrisk
from avrisk.api import backends
from avrisk.api.backends import backend_descriptions
from avrisk.cli.backends import BackendName
from avrisk.registry import UnknownComponentError
from tests.scenario_files import shortened_scenario

FAST = dict(method="naive", n_final=300, batch_size=300, seed=4, failures=0)


@pytest.fixture
def own_registry(monkeypatch):
    """Backends registered by the test are gone after it."""
    for table in ("_factories", "_descriptions"):
        monkeypatch.setattr(
            backends.BACKENDS, table, copy.copy(getattr(backends.BACKENDS, table))
        )


@pytest.fixture
def user_backend(own_registry, monkeypatch):
    """``tests.user_backend`` imported afresh (its registration and log new)."""
    assert "serial" not in backend_descriptions(), "imported elsewhere"
    monkeypatch.delitem(sys.modules, "tests.user_backend", raising=False)
    module = importlib.import_module("tests.user_backend")
    yield module
    sys.modules.pop("tests.user_backend", None)


def test_a_registered_backend_runs_the_estimate_of_this_process(tmp_path, user_backend):
    assert backend_descriptions()["serial"] == "this process, chunk by chunk"

    scenario = shortened_scenario(tmp_path, 0.5)
    ran = avrisk.estimate(scenario, out=tmp_path / "serial", backend="serial",
                          workers=2, **FAST)  # fmt: skip
    assert user_backend.CALLS == [("opened", 2, None), ("closed",)]
    default = avrisk.estimate(scenario, out=tmp_path / "default", **FAST)
    drop = {"wall_time_s"}
    assert {k: v for k, v in ran.estimate.items() if k not in drop} == {
        k: v for k, v in default.estimate.items() if k not in drop
    }


def test_an_unknown_backend_lists_the_registered_ones(tmp_path):
    scenario = shortened_scenario(tmp_path, 0.5)
    with pytest.raises(UnknownComponentError, match="known: local, ray"):
        avrisk.estimate(scenario, out=tmp_path / "run", backend="rya", **FAST)
    assert not (tmp_path / "run").exists()


def test_the_command_line_offers_every_registered_backend():
    assert list(BackendName) == list(backend_descriptions())
