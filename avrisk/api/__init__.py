"""The scenario-level Python API: what the ``avrisk`` commands do, as calls.

Each call takes a scenario (a bundled name, a YAML path, a
:class:`~avrisk.scenario.ScenarioSpec` or its data), prints nothing, reports
progress to an optional callback (:mod:`avrisk.api.events`) and returns a
typed result; a problem the caller can fix raises
:class:`~avrisk.api.errors.UserError` (one sentence). The run directories are
those of ``avrisk run``: calling :func:`estimate` again with the same
arguments resumes an interrupted run, or reads a finished one back (the
README's "Python API" shows one in five lines).

This module imports only the standard library: the simulator (torch) is
loaded by the first call.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from avrisk.api.errors import UserError
from avrisk.api.events import Progress, ignore

if TYPE_CHECKING:
    from avrisk.api.ab import ABResult
    from avrisk.api.result import EstimationResult, Scenario
    from avrisk.api.rollouts import SimulationRun
    from avrisk.scenario import ScenarioSpec

__all__ = [
    "UserError",
    "compare_egos",
    "compare_methods",
    "estimate",
    "simulate",
    "write_report",
]


def _spec(scenario: Scenario, ego: str | Mapping[str, Any] | None) -> ScenarioSpec:
    """The scenario, its ego replaced by ``ego`` (a policy name or its spec)."""
    from avrisk.api.result import scenario_spec
    from avrisk.scenario import spec_from_dict

    spec = scenario_spec(scenario)
    if ego is None:
        return spec
    data = spec.model_dump(mode="json")
    data["ego"] = {"policy": ego} if isinstance(ego, str) else dict(ego)
    return spec_from_dict(data, source=f"{spec.name} with ego {data['ego']}")


def _settings(
    method: str | None,
    gamma: float,
    gamma_test: Sequence[float],
    seed: int,
    batch_size: int,
    options: dict[str, Any],
) -> Any:
    """Validated :class:`~avrisk.pipeline.RunSettings` of a call."""
    from avrisk.api.runs import settings
    from avrisk.rare.estimator import DEFAULT_METHOD

    return settings(
        method or DEFAULT_METHOD,
        gamma=gamma,
        gamma_test=tuple(gamma_test),
        seed=seed,
        batch_size=batch_size,
        **options,
    )


def estimate(
    scenario: Scenario,
    *,
    method: str | None = None,
    out: str | Path = "runs/latest",
    gamma: float = 0.14,
    gamma_test: Sequence[float] = (0.1, 0.2, 0.3),
    seed: int = 0,
    batch_size: int = 4096,
    ego: str | Mapping[str, Any] | None = None,
    device: str = "cpu",
    failures: int = 6,
    store_full: bool = False,
    workers: int | None = None,
    backend: str = "local",
    address: str | None = None,
    progress: Progress = ignore,
    **options: Any,
) -> EstimationResult:
    """Estimate ``P0(min TTC <= gamma)`` of a scenario, as ``avrisk run`` does.

    Parameters
    ----------
    scenario : str, Path, ScenarioSpec or dict
        A bundled scenario's name, a YAML file, or a spec.
    method : str, optional
        A registered estimator (:func:`avrisk.rare.estimator_names`);
        default ``splitting_is``.
    out : str or Path, default="runs/latest"
        The run directory: created, resumed, or read back when complete.
    gamma : float, default=0.14
        The threshold on the minimum TTC [s].
    gamma_test : sequence of float, default=(0.1, 0.2, 0.3)
        Further thresholds [s], estimated from the same rollouts.
    seed, batch_size : int
        The run's seed, and the rollouts simulated together.
    ego : str or mapping, optional
        The ego under test in place of the scenario's: a registered policy
        name (:func:`avrisk.agents.policy.register_policy`), an import path
        ``"package.module:Class"``, or ``{"policy": ..., "params": {...}}``.
    device : str, default="cpu"
        Torch device of the simulator.
    failures : int, default=6
        Most likely failures recorded and animated in the report (0: none).
    store_full : bool, default=False
        Store every column of the samples (else ``xi`` is drawn again when read).
    workers, backend, address
        Simulate in worker processes (``backend="local"``), on a Ray cluster
        (``backend="ray"``, ``address``) or with another registered backend
        (:func:`avrisk.api.backends.register_backend`); default: in this process.
    progress : callable, optional
        Called with every :mod:`avrisk.api.events` event, in order.
    **options
        The estimator's settings by name (``n_final=2000``, ``rho=0.05``) and
        the stopping rules (``rel_half_width``, ``max_rollouts``,
        ``max_seconds``); an estimator's own defaults otherwise.

    Returns
    -------
    EstimationResult
        The run and its report: ``p``, ``ci``, ``by_gamma``, ``answer()``,
        ``document()`` (the ``--json`` document).

    Raises
    ------
    UserError
        For settings, a scenario or a run directory that cannot be used.
    """
    from avrisk.api.runs import estimate_spec

    return estimate_spec(
        _spec(scenario, ego),
        _settings(method, gamma, gamma_test, seed, batch_size, options),
        Path(out),
        failures=failures,
        store_full=store_full,
        device=device,
        backend=(backend, workers, address),
        progress=progress,
    )


def compare_methods(
    scenario: Scenario,
    *,
    method: str | None = None,
    out: str | Path = "runs/compare",
    reference_n: int = 50_000,
    gamma: float = 0.14,
    gamma_test: Sequence[float] = (0.1, 0.2, 0.3),
    seed: int = 0,
    batch_size: int = 4096,
    ego: str | Mapping[str, Any] | None = None,
    device: str = "cpu",
    failures: int = 6,
    workers: int | None = None,
    backend: str = "local",
    address: str | None = None,
    progress: Progress = ignore,
    **options: Any,
) -> EstimationResult:
    """A method against naive Monte Carlo at its budget, as ``avrisk compare``.

    The method's run goes to ``out/<method>``, naive MC with as many
    rollouts to ``out/naive`` and a naive reference of ``reference_n``
    rollouts (0: none) to ``out/reference``; the report compares them per
    threshold (``ratios``). The other parameters are :func:`estimate`'s.
    """
    from avrisk.api.runs import compare_runs

    return compare_runs(
        _spec(scenario, ego),
        Path(out),
        _settings(method, gamma, gamma_test, seed, batch_size, options),
        reference_n,
        failures,
        device,
        (backend, workers, address),
        progress=progress,
    )


def compare_egos(
    scenario: Scenario,
    ego_a: str | Mapping[str, Any] | None,
    ego_b: str | Mapping[str, Any],
    *,
    out: str | Path = "runs/ab",
    max_ratio: float = 1.0,
    gamma: float = 0.14,
    seed: int = 0,
    batch_size: int = 4096,
    failures: int = 3,
    device: str = "cpu",
    workers: int | None = None,
    backend: str = "local",
    address: str | None = None,
    progress: Progress = ignore,
    **options: Any,
) -> ABResult:
    """Is ego B at most ``max_ratio`` times as risky as ego A? As ``avrisk ab``.

    Both egos drive every draw of ``X`` with the same seed (common random
    numbers); ``splitting_is`` searches the union of their failure sets and
    one weighted sample gives ``p_A``, ``p_B``, ``p_B - p_A``, ``p_B / p_A``
    and the regressions and fixes (:mod:`avrisk.rare.paired`); the gate
    passes when the one-sided upper 95% bound of ``p_B / p_A`` is at most
    ``max_ratio``, fails when the lower one is above it.

    Parameters
    ----------
    scenario : str, Path, ScenarioSpec or dict
        The scenario; its own ego is replaced by each of the two.
    ego_a, ego_b : str or mapping
        Each ego as :func:`estimate`'s ``ego``: a registered policy name, an
        import path ``"package.module:Class"``, or ``{"policy": ...,
        "params": {...}}`` (an external ZeroMQ server: ``{"policy":
        "external", "params": {"address": ...}}``); ``ego_a`` None: the
        scenario's own ego.
    out : str or Path, default="runs/ab"
        The run directory: created, resumed, or read back when complete.
    max_ratio : float, default=1.0
        The gate's margin on ``p_B / p_A``.
    gamma : float, default=0.14
        The threshold on both egos' minimum TTC [s].
    seed, batch_size, device, progress
        As for :func:`estimate`.
    failures : int, default=3
        Regressions (and fixes) the report ``ab_report.html`` animates, each
        with both egos on the same situation, the most realistic first.
    workers, backend, address
        As for :func:`estimate`: each worker simulates both egos on its
        chunks; the result is the same bit for bit wherever they run.
    **options
        ``splitting_is``'s settings by name (``n_final=20000``), over the
        paired defaults (:data:`avrisk.rare.paired.PAIRED_DEFAULTS`).

    Returns
    -------
    ABResult
        ``paired`` (the estimates), ``verdict``, ``line()`` for a CI log and
        ``document()`` (``ab.json``, ``--json``).

    Raises
    ------
    UserError
        For settings, egos, a scenario or a run directory that cannot be used.
    """
    from avrisk.api.ab import compare_specs
    from avrisk.api.result import scenario_spec
    from avrisk.rare.paired import PAIRED_DEFAULTS, UNION_METHOD

    options = {**PAIRED_DEFAULTS, **options}
    spec = scenario_spec(scenario)
    if ego_a is None:
        ego_a = spec.ego.model_dump(mode="json")
    return compare_specs(
        _spec(spec, ego_a),
        _spec(spec, ego_b),
        _settings(UNION_METHOD, gamma, (), seed, batch_size, options),
        Path(out),
        max_ratio=max_ratio,
        failures=failures,
        device=device,
        backend=(backend, workers, address),
        progress=progress,
    )


def simulate(
    scenario: Scenario,
    n: int,
    *,
    seed: int = 0,
    batch_size: int = 1024,
    ego: str | Mapping[str, Any] | None = None,
    device: str = "cpu",
    on_batch: Callable[[int], None] | None = None,
) -> SimulationRun:
    """``n`` naive rollouts from ``P0``, one row each, as ``avrisk simulate``.

    ``on_batch`` is called with the number of rollouts finished after each
    chunk; the result's ``table`` is what ``avrisk simulate`` writes
    (:func:`avrisk.pipeline.files.write_parquet_atomic` writes it too).
    """
    from avrisk.api.rollouts import simulate_rollouts

    return simulate_rollouts(
        _spec(scenario, ego),
        n,
        seed=seed,
        batch_size=batch_size,
        device=device,
        on_batch=on_batch,
    )


def write_report(
    run_dir: str | Path,
    *,
    failures: int | None = None,
    scenario: Scenario | None = None,
    device: str = "cpu",
) -> Path:
    """The HTML report of a finished run or comparison, written again; its path.

    Failures are animated from the traces recorded during the run (``failures``
    of them, default 6); a scenario that names user code must be given again
    (``scenario``) only to animate failures without recorded traces. Of an
    A/B comparison (:func:`compare_egos`), ``ab_report.html`` and ``ab.json``
    are written again as it wrote them, with ``failures`` regressions and
    fixes animated each (default: as many as it animated).
    """
    from avrisk.api.rebuild import rebuild

    path = rebuild(Path(run_dir), failures, scenario, device).report
    assert path is not None
    return path
