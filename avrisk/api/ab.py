"""Is the new release safer? Two egos compared on the same draws (``avrisk ab``).

:func:`compare_specs` runs the scenario with ego ``A`` and ego ``B`` on every
draw of ``X`` and its seed (:class:`avrisk.assembly.paired.PairedObjective`:
common random numbers), searches the union of their failure sets with
``splitting_is`` on the lower of the two minimum TTCs, and estimates ``p_A``,
``p_B``, their difference and ratio, the regressions and fixes from its one
weighted final sample (:mod:`avrisk.rare.paired`). A gate reads the ratio's
one-sided bounds against a margin (:func:`avrisk.rare.paired.gate`).

The run directory is ``avrisk run``'s: each rollout pair a row of
``samples.parquet`` (``f`` the lower minimum TTC, ``f_a`` and ``f_b`` each
ego's, and each ego's outcome columns), resumed when the same call is made
again; a resume checks both egos, by their specs in ``config.json`` and by
replaying recorded pairs. The paired estimate goes to ``ab.json``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from avrisk.api.backends import open_evaluator
from avrisk.api.errors import UserError, write_failures
from avrisk.api.events import Progress, ignore, run_events
from avrisk.api.readback import check_recorded
from avrisk.api.result import samples_directory
from avrisk.api.runs import (
    IN_PROCESS,
    BackendChoice,
    check_thresholds,
    plan,
    planned,
)
from avrisk.assembly import (
    MECHANISMS,
    ScenarioSimulator,
    SimulationObjective,
    base_distribution,
    param_layout,
    scenario_typicality,
)
from avrisk.assembly.paired import PairedObjective
from avrisk.pipeline import RunDirectory, RunSettings, run_estimation
from avrisk.pipeline.files import write_json
from avrisk.pipeline.provenance import stamp
from avrisk.pipeline.repeatability import ReplayCheck
from avrisk.rare.evaluation import Evaluator
from avrisk.rare.families.base import ExponentialFamily
from avrisk.rare.mixture_controls import mixture_controls
from avrisk.rare.paired import (
    PAIR_COLUMNS,
    UNION_METHOD,
    MinOfPair,
    PairedEstimate,
    PairedSample,
    paired_estimate,
)
from avrisk.rare.paired_gate import Verdict, gate
from avrisk.rare.problem import FINAL_STAGE, STATUS
from avrisk.rare.proposals import mixture_from_estimate
from avrisk.rare.results import jsonable
from avrisk.report.ab import AB_REPORT_FILE, write_ab_report
from avrisk.report.animate import animate_pair, animate_samples
from avrisk.report.answer import SCENARIO_WORDING
from avrisk.scenario import ScenarioSpec

__all__ = [
    "AB_FILE",
    "AB_SCHEMA",
    "PAIR_UNITS",
    "ABResult",
    "compare_specs",
    "conclude",
    "final_sample",
]

#: The paired estimate and the verdict, in the run directory.
AB_FILE = "ab.json"
#: Schema of ``ab.json`` and of ``avrisk ab --json``.
AB_SCHEMA = "avrisk.ab/1"
#: The units of the outputs an A/B run records beside ``f``.
PAIR_UNITS = {"f_a": "s", "f_b": "s"}
#: The run's label in progress events.
LABEL = "A/B (both egos per rollout)"


@dataclass(frozen=True)
class ABResult:
    """Two egos compared on one scenario: the estimate, the verdict, the files.

    Attributes
    ----------
    scenario : str
        The scenario's name.
    egos : (dict, dict)
        Ego ``A``'s and ego ``B``'s specs (``policy``, ``params``).
    paired : PairedEstimate
        ``p_A``, ``p_B``, difference, ratio, regressions and fixes.
    verdict : Verdict
        The gate's outcome at ``max_ratio``.
    path : Path
        The run directory.
    discordant : dict
        ``"regressions"`` and ``"fixes"``: the final stage's discordant
        rollouts, the most realistic first (:func:`ranked_discordant`).
    animated : int
        Regressions and fixes (each) the report animates.
    report : Path or None
        The HTML report.
    """

    scenario: str
    egos: tuple[dict[str, Any], dict[str, Any]]
    paired: PairedEstimate
    verdict: Verdict
    path: Path
    discordant: dict[str, list[dict[str, Any]]]
    animated: int
    report: Path | None = None

    def line(self) -> str:
        """One line for a CI log: the outcome, the ratio's bound, both ``p``."""
        v, est = self.verdict, self.paired
        if v.outcome == "pass":
            why = f"upper 95% bound {v.upper:.3g} <= {v.max_ratio:g}"
        elif v.outcome == "fail":
            why = f"lower 95% bound {v.lower:.3g} > {v.max_ratio:g}"
        else:
            why = f"95% bounds [{v.lower:.3g}, {v.upper:.3g}] straddle {v.max_ratio:g}"
            if v.n_final_needed is not None:
                why += f"; about n_final={v.n_final_needed:,} would likely decide"
        return (
            f"{v.outcome.upper()}: p_B/p_A = {est.ratio.value:.3g} ({why}); "
            f"p_A = {est.a.p:.3g}, p_B = {est.b.p:.3g}, {est.n_evals:,} rollout "
            f"pairs; trust {est.trust.word}"
        )

    def document(self) -> dict[str, Any]:
        """Every figure, as ``ab.json`` and ``--json`` hold it (:data:`AB_SCHEMA`)."""
        return {
            "schema": AB_SCHEMA,
            "scenario": self.scenario,
            "ego_a": self.egos[0],
            "ego_b": self.egos[1],
            "verdict": self.verdict.to_dict(),
            "line": self.line(),
            "paired": self.paired.to_dict(),
            "discordant": jsonable(self.discordant),
            "animated": self.animated,
            "path": str(self.path),
            "report": None if self.report is None else str(self.report),
        }

    def __str__(self) -> str:
        return self.line()


def final_sample(
    run_dir: RunDirectory,
    base: ExponentialFamily | None = None,
    proposal: Any = None,
) -> PairedSample:
    """The final stage of a finished paired run, both egos' values, from its table.

    With ``base`` (the run's ``P0``) and ``proposal`` (the union estimate's
    description of its proposal, ``estimate["proposal"]``), the proposal's
    control variates too: only if the proposal read back gives every final
    sample the density the run recorded (else none).
    """
    columns = ["stage", "log_weight", "log_p_proposal", *PAIR_COLUMNS, STATUS]
    table = run_dir.samples(columns)
    final = np.asarray(table["stage"]) == FINAL_STAGE

    def column(name: str) -> np.ndarray:
        return np.asarray(table[name].to_numpy(zero_copy_only=False))[final]

    log_q = column("log_p_proposal").astype(np.float64)
    controls = np.empty((log_q.size, 0))
    if base is not None and proposal is not None:
        x = run_dir.samples(run_dir.param_names, rows=np.flatnonzero(final))
        controls = _recorded_controls(base, proposal, _matrix(x), log_q)
    return PairedSample(
        column("log_weight").astype(np.float64),
        column("f_a").astype(np.float64),
        column("f_b").astype(np.float64),
        column(STATUS) != 0,
        controls,
    )


#: How far (in log-density) a proposal read back may be from the recorded one.
DENSITY_TOLERANCE = 1e-8


def _recorded_controls(
    base: ExponentialFamily, proposal: Any, x: np.ndarray, log_q: np.ndarray
) -> np.ndarray:
    """The control variates of ``proposal`` at ``x``, where its densities match."""
    try:
        mixture = mixture_from_estimate(proposal, base)
    except ValueError:
        return np.empty((len(x), 0))
    if not np.allclose(mixture.log_prob(x), log_q, rtol=0.0, atol=DENSITY_TOLERANCE):
        return np.empty((len(x), 0))
    return mixture_controls(mixture, x)


def _matrix(table: Any) -> np.ndarray:
    """A table's columns side by side, float64, shape (rows, columns)."""
    return np.column_stack(
        [
            np.asarray(c.to_numpy(zero_copy_only=False), dtype=np.float64)
            for c in table.columns
        ]
    )


def compare_specs(
    spec_a: ScenarioSpec,
    spec_b: ScenarioSpec,
    run_settings: RunSettings,
    out: Path,
    *,
    max_ratio: float = 1.0,
    failures: int = 3,
    device: str = "cpu",
    backend: BackendChoice = IN_PROCESS,
    progress: Progress = ignore,
) -> ABResult:
    """Run (or resume, or read back) the comparison of two egos into ``out``.

    Then ``ab.json`` and the report ``ab_report.html``: the discordant
    rollouts ranked, the first ``failures`` regressions and fixes animated
    with each ego on the same situation.

    Parameters
    ----------
    spec_a, spec_b : ScenarioSpec
        The scenario with ego ``A`` and with ego ``B`` (nothing else may differ).
    run_settings : RunSettings
        Of ``splitting_is`` (the union's search); its ``gamma`` is both egos'.
    out : Path
        The run directory.
    max_ratio : float, default=1.0
        The gate's margin on ``p_B / p_A``.
    failures : int, default=3
        Regressions and fixes animated in the report (each, 0: none).
    device : str, default="cpu"
    backend : BackendChoice, default: in this process
        Where the rollout pairs are simulated
        (:func:`avrisk.api.backends.open_evaluator`): each worker builds both
        egos and evaluates a chunk as this process would, so the result is
        the same bit for bit on every backend.
    progress : callable, optional
        The plan, then the run's events (:mod:`avrisk.api.events`).
    """
    if run_settings.method != UNION_METHOD:
        raise UserError(f"an A/B comparison searches with {UNION_METHOD}")
    check_thresholds(spec_a, run_settings)
    objective = PairedObjective(
        SimulationObjective(spec_a, device=device, allow_import=True),
        SimulationObjective(spec_b, device=device, allow_import=True),
    )
    progress(plan(spec_a, [planned(LABEL, run_settings)]))
    with open_evaluator(objective, *backend) as evaluator:
        run_dir, summary = run_pairs(out, objective, run_settings, evaluator, progress)
    return conclude(
        run_dir,
        (spec_a, spec_b),
        summary["estimate"],
        max_ratio,
        failures,
        _simulators(objective),
    )


def conclude(
    run_dir: RunDirectory,
    specs: tuple[ScenarioSpec, ScenarioSpec],
    estimate: dict[str, Any],
    max_ratio: float,
    failures: int,
    simulators: tuple[ScenarioSimulator | None, ScenarioSimulator | None],
) -> ABResult:
    """The comparison in a finished paired run directory: ``ab.json``, the report.

    What ``avrisk ab`` writes after its run, and ``avrisk report`` again from
    the directory alone (:func:`avrisk.api.rebuild.rebuild_ab_report`): the
    paired estimate of the final stage, with the union's ``estimate`` (the
    run summary's; its ``gamma`` both egos'), the gate at ``max_ratio``, the
    discordant rollouts ranked, and the first ``failures`` of each kind
    animated by each ego's simulator (``specs`` and ``simulators``: A's,
    B's; an animation not made yet is left out where its simulator is None).
    """
    out, gamma = run_dir.path, float(estimate["gamma"])
    sample = final_sample(
        run_dir, base_distribution(specs[0]), estimate.get("proposal")
    )
    paired = paired_estimate(sample, gamma, estimate, SCENARIO_WORDING)
    discordant = ranked_discordant(run_dir, specs[0], gamma)
    egos = [spec.ego.model_dump(mode="json") for spec in specs]
    then = "the comparison is complete: free space and rerun"
    with write_failures(out, then):
        animated = animate_discordant(run_dir, simulators, discordant, failures)
        result = ABResult(
            specs[0].name,
            (egos[0], egos[1]),
            paired,
            gate(paired, max_ratio),
            out,
            discordant,
            failures,
            out / AB_REPORT_FILE,
        )
        write_json(out / AB_FILE, result.document())
        write_ab_report(out, result.document(), jsonable(animated))
    return result


def run_pairs(
    out: Path,
    objective: PairedObjective,
    run_settings: RunSettings,
    evaluator: Evaluator | None,
    progress: Progress,
) -> tuple[RunDirectory, dict[str, Any]]:
    """Run (or resume, or read back) the paired search into ``out``; its summary.

    ``evaluator``: where the chunks are simulated (None: this process). A
    resume replays recorded pairs in this process (both egos checked).
    """
    spec_a, spec_b = (o.simulator.spec for o in objective.objectives)
    check_recorded(out)
    run_dir = samples_directory(out, spec_a, outputs=PAIR_UNITS)
    f = MinOfPair(objective)
    definition = objective.definition()
    resume = "what was recorded is kept: free space and rerun the same command"
    with write_failures(out, resume), run_events(LABEL, out, progress) as monitor:
        summary = run_estimation(
            run_dir,
            base_distribution(spec_a),
            f,
            run_settings,
            context={
                "scenario": spec_a.model_dump(mode="json"),
                "ego_a": spec_a.ego.model_dump(mode="json"),
                "ego_b": spec_b.ego.model_dump(mode="json"),
                "defines_p": definition,
            },
            monitor=monitor,
            evaluator=evaluator,
            provenance=stamp(definition, objective.computed_with()),
            replay_check=ReplayCheck(
                f,
                fresh=not objective.deterministic,
                tolerance=objective.replay_tolerance,
            ),
        )
    return run_dir, summary


def ranked_discordant(
    run_dir: RunDirectory, spec: ScenarioSpec, gamma: float
) -> dict[str, list[dict[str, Any]]]:
    """The final stage's discordant rollouts, the most realistic first.

    Regressions: ``f_B <= gamma < f_A``; fixes: the reverse (rollouts that
    failed to evaluate left out). Ranked as the report ranks failures
    (:meth:`~avrisk.assembly.typicality.Typicality.rank`: the lower of the
    start's and the drivers' percentiles under P0, then ``log p0``). Each row:
    ``row`` (in ``samples.parquet``), ``seed``, ``f_a``, ``f_b`` [s],
    ``weight``, ``log_p0``, ``percentile`` and ``mechanism`` (the failing
    ego's contact, :data:`~avrisk.assembly.MECHANISMS`).
    """
    column, names = MECHANISMS
    table = run_dir.samples(
        ["stage", "seed", "log_p0", "weight", *PAIR_COLUMNS, STATUS]
        + [f"{column}_a", f"{column}_b"]
    )
    get = {
        name: np.asarray(table[name].to_numpy(zero_copy_only=False))
        for name in table.column_names
    }
    usable = (get["stage"] == FINAL_STAGE) & (get[STATUS] == 0)
    fails_a, fails_b = get["f_a"] <= gamma, get["f_b"] <= gamma
    kinds = {
        "regressions": (usable & fails_b & ~fails_a, "_b"),
        "fixes": (usable & fails_a & ~fails_b, "_a"),
    }
    typical = scenario_typicality(spec)
    columns = param_layout(spec).columns
    out: dict[str, list[dict[str, Any]]] = {}
    for kind, (mask, failing) in kinds.items():
        rows = np.flatnonzero(mask)
        if not rows.size:
            out[kind] = []
            continue
        x = run_dir.samples(columns, rows=rows)
        situation = np.stack(
            [
                np.asarray(x[c], dtype=np.float64)
                for c in columns[: typical.n_situation]
            ],
            axis=1,
        )
        keys = typical.rank(situation, get["log_p0"][rows])
        order = np.lexsort((keys[:, 1], keys[:, 0]))[::-1]
        out[kind] = [
            {
                "row": int(rows[i]),
                "seed": int(get["seed"][rows[i]]),
                "f_a": float(get["f_a"][rows[i]]),
                "f_b": float(get["f_b"][rows[i]]),
                "weight": float(get["weight"][rows[i]]),
                "log_p0": float(get["log_p0"][rows[i]]),
                "percentile": float(keys[i, 0]),
                "mechanism": names.get(int(get[column + failing][rows[i]]), names[-1]),
            }
            for i in order
        ]
    return out


def animate_discordant(
    run_dir: RunDirectory,
    simulators: tuple[ScenarioSimulator | None, ScenarioSimulator | None],
    discordant: dict[str, list[dict[str, Any]]],
    n: int,
) -> dict[str, list[dict[str, Any]]]:
    """The first ``n`` of each kind, with A and B on the same ``X`` animated.

    One GIF, ``<run_dir>/ab/<kind><i>.gif``, plays A's rollout above B's, in
    step (:func:`~avrisk.report.animate.animate_pair`); the row gets its path,
    relative to the run directory, as ``animation``. Where one of
    ``simulators`` (A's, B's) is None (a read-back that cannot build an ego
    from user code) and that GIF is not there, each ego it can simulate gets
    a GIF of its own, ``<kind><i>_<a|b>.gif``, as ``animation_a`` and
    ``animation_b`` (None for the other). A GIF already there is kept: a
    read-back does not simulate it again.
    """
    out = run_dir.path
    columns = list(run_dir.param_names)
    shown: dict[str, list[dict[str, Any]]] = {}
    for kind, rows in discordant.items():
        shown[kind] = []
        for i, row in enumerate(rows[:n], start=1):
            x = run_dir.samples(columns, rows=[row["row"]]).to_pylist()[0]
            sample = {**x, "seed": row["seed"]}
            pair = out / "ab" / f"{kind}{i}.gif"
            if not pair.is_file() and None not in simulators:
                animate_pair(simulators, sample, ("A", "B"), pair)  # type: ignore[arg-type]
            if pair.is_file():
                shown[kind].append({**row, "animation": str(pair.relative_to(out))})
                continue
            paths: dict[str, str | None] = {}
            for side, sim in zip("ab", simulators, strict=True):
                path = out / "ab" / f"{kind}{i}_{side}.gif"
                if not path.is_file() and sim is not None:
                    animate_samples(sim, [sample], path)
                paths[f"animation_{side}"] = (
                    str(path.relative_to(out)) if path.is_file() else None
                )
            shown[kind].append({**row, **paths})
    return shown


def _simulators(
    objective: PairedObjective,
) -> tuple[ScenarioSimulator, ScenarioSimulator]:
    """Each ego's simulator."""
    return objective.a.simulator, objective.b.simulator
