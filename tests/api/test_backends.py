"""Backends by name: a new one is one registration, run like the bundled ones."""

import copy
from contextlib import contextmanager

import pytest

import avrisk
from avrisk.api import backends
from avrisk.api.backends import backend_descriptions, register_backend
from avrisk.cli.backends import BackendName
from avrisk.rare.evaluation import LocalEvaluator
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


def test_a_registered_backend_runs_the_estimate_of_this_process(tmp_path, own_registry):
    calls = []

    @contextmanager
    def serial(objective, workers, address):
        calls.append(("opened", workers, address))
        yield LocalEvaluator()
        calls.append(("closed",))

    register_backend("serial", serial, description="this process, chunk by chunk")
    assert backend_descriptions()["serial"] == "this process, chunk by chunk"

    scenario = shortened_scenario(tmp_path, 0.5)
    ran = avrisk.estimate(scenario, out=tmp_path / "serial", backend="serial",
                          workers=2, **FAST)  # fmt: skip
    assert calls == [("opened", 2, None), ("closed",)]
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
