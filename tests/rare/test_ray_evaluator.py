"""The Ray backend on a local cluster bound to 127.0.0.1 (``pytest -m ray``)."""

import json
import os
import signal
import threading
import time
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import pyarrow.parquet as pq
import pytest
import yaml
from typer.testing import CliRunner

from avrisk.rare import cross_entropy, naive_mc
from avrisk.rare.parallel import EVALUATED_BY
from avrisk.rare.problem import SAMPLE_CHUNK
from avrisk.rare.ray_evaluator import LOOPBACK_ONLY, RayEvaluator
from avrisk.testing import gaussian_linear_problem

os.environ.update(LOOPBACK_ONLY)  # before ray is imported: servers on 127.0.0.1
ray = pytest.importorskip("ray", reason="Ray is not installed: pip install avrisk[ray]")
pytestmark = pytest.mark.ray

PROBLEM = gaussian_linear_problem(3, p=1e-4)


@dataclass(frozen=True)
class SlowFactory:
    """PROBLEM.f, taking ``delay`` seconds per call; each calling worker process
    leaves a file named by its pid in ``pids``."""

    pids: str
    delay: float = 0.0

    def __call__(self):
        f = gaussian_linear_problem(3, p=1e-4).f

        def slow(x):
            Path(self.pids, str(os.getpid())).touch()
            time.sleep(self.delay)
            return f(x)

        return slow


@pytest.fixture(scope="module")
def cluster():
    """Two CPUs, loopback only; workers import this module (on their path)."""
    previous = os.environ.get("PYTHONPATH")
    here = str(Path(__file__).parent)
    os.environ["PYTHONPATH"] = os.pathsep.join(p for p in (here, previous) if p)
    ray.init(
        num_cpus=2,
        include_dashboard=False,
        _node_ip_address="127.0.0.1",
        log_to_driver=False,
    )
    yield
    ray.shutdown()
    if previous is None:
        os.environ.pop("PYTHONPATH")
    else:
        os.environ["PYTHONPATH"] = previous


def without_time(result):
    return result.to_dict() | {"wall_time_s": 0}


def test_ray_gives_the_local_result_bit_for_bit(cluster, tmp_path):
    def run(evaluator=None):
        return cross_entropy(
            PROBLEM.f,
            PROBLEM.base,
            PROBLEM.gamma,
            rho=0.1,
            n_per_iter=SAMPLE_CHUNK + 100,
            n_iter=2,
            n_final=SAMPLE_CHUNK + 100,
            seed=5,
            evaluator=evaluator,
        )

    with RayEvaluator(SlowFactory(str(tmp_path)), workers=2) as evaluator:
        assert without_time(run(evaluator)) == without_time(run())


def test_a_worker_killed_mid_stage_loses_no_chunk_and_duplicates_none(
    cluster, tmp_path
):
    killed = []

    def kill_the_first_worker():
        deadline = time.monotonic() + 120
        while not any(tmp_path.iterdir()) and time.monotonic() < deadline:
            time.sleep(0.02)
        victim = int(next(tmp_path.iterdir()).name)
        os.kill(victim, signal.SIGKILL)  # in the middle of its first chunk
        killed.append(victim)

    killer = threading.Thread(target=kill_the_first_worker, daemon=True)
    killer.start()
    batches = []
    n = 4 * SAMPLE_CHUNK
    with RayEvaluator(SlowFactory(str(tmp_path), delay=1.0), workers=2) as evaluator:
        result = naive_mc(
            PROBLEM.f,
            PROBLEM.base,
            PROBLEM.gamma,
            n,
            seed=8,
            on_batch=batches.append,
            evaluator=evaluator,
        )
    killer.join()
    assert killed
    assert sorted(b.chunk for b in batches) == [0, 1, 2, 3]
    labels = {str(b.extras[EVALUATED_BY][0]) for b in batches}
    assert all(label.startswith("ray ") for label in labels)
    assert not any(f"pid {killed[0]} " in label + " " for label in labels)
    local = naive_mc(PROBLEM.f, PROBLEM.base, PROBLEM.gamma, n, seed=8)
    assert without_time(result) == without_time(local)


def test_avrisk_run_on_ray_gives_the_in_process_numbers(cluster, tmp_path):
    from avrisk.cli.app import app  # not at the top: Ray workers import this module

    text = resources.files("avrisk.data.scenarios").joinpath("highway_idm.yaml")
    spec = yaml.safe_load(text.read_text())
    spec["simulation"]["horizon"] = 0.5
    scenario = tmp_path / "tiny.yaml"
    scenario.write_text(yaml.safe_dump(spec))
    args = ("--method", "naive", "--n-final", 8200, "--seed", 4, "--failures", 0)
    tables = {}
    for name, backend in {"here": (), "ray": ("--backend", "ray")}.items():
        out = tmp_path / name
        result = CliRunner().invoke(
            app, [str(a) for a in ("run", scenario, "--out", out, *args, *backend)]
        )
        assert result.exit_code == 0, result.output
        estimate = json.loads((out / "summary.json").read_text())["estimate"]
        tables[name] = (pq.read_table(out / "samples.parquet"), estimate)
    (here, here_estimate), (on_ray, ray_estimate) = tables["here"], tables["ray"]
    assert ray_estimate | {"wall_time_s": 0} == here_estimate | {"wall_time_s": 0}
    assert on_ray.drop([EVALUATED_BY]).equals(here)
    assert all(s.startswith("ray ") for s in on_ray[EVALUATED_BY].to_pylist())


def test_an_ab_comparison_on_ray_gives_the_in_process_numbers(cluster, tmp_path):
    import avrisk  # not at the top: Ray workers import this module

    text = resources.files("avrisk.data.scenarios").joinpath("highway_idm.yaml")
    spec = yaml.safe_load(text.read_text())
    spec["simulation"]["horizon"] = 4.0
    holds_speed = {"policy": "constant", "params": {"accel": 0.0}}
    small = dict(gamma=2.0, n_particles=100, n_final=200, batch_size=200, failures=0)
    runs = {}
    for name, backend in {"here": {}, "ray": {"backend": "ray"}}.items():
        out = tmp_path / name
        result = avrisk.compare_egos(
            spec, "idm_mobil", holds_speed, out=out, **small, **backend
        )
        runs[name] = result, pq.read_table(out / "samples.parquet")
    (here, here_table), (on_ray, ray_table) = runs["here"], runs["ray"]
    assert (on_ray.paired.a.p, on_ray.paired.b.p) == (here.paired.a.p, here.paired.b.p)
    assert on_ray.paired.difference == here.paired.difference
    assert on_ray.paired.ratio == here.paired.ratio
    assert ray_table.drop([EVALUATED_BY]).equals(here_table)
    assert all(s.startswith("ray ") for s in ray_table[EVALUATED_BY].to_pylist())
