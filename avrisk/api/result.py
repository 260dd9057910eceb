"""What the scenario-level calls take and return.

A scenario is given as a bundled name, a YAML path, a spec or its data
(:func:`scenario_spec`); its samples go to a run directory that records their
units and draws the learned drivers' large blocks again (:func:`samples_directory`);
complete runs and their report come back as an :class:`EstimationResult`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from avrisk.api.document import Runs, answer, result_document
from avrisk.assembly import base_distribution, param_layout
from avrisk.pipeline import RunDirectory
from avrisk.rare import Product
from avrisk.rare.estimator import estimator_class
from avrisk.report.answer import Headline
from avrisk.scenario import ScenarioSpec, load_spec, spec_from_dict

__all__ = [
    "NAIVE_PART",
    "REFERENCE_PART",
    "EstimationResult",
    "Scenario",
    "method_label",
    "samples_directory",
    "scenario_spec",
]

Scenario = str | Path | ScenarioSpec | dict[str, Any]

#: Sub-directories of a comparison besides the tested method's own.
NAIVE_PART, REFERENCE_PART = "naive", "reference"


def method_label(method: str) -> str:
    """The human name of a registered estimator (``"cross-entropy"``)."""
    return estimator_class(method).label


def samples_directory(
    out: Path,
    spec: ScenarioSpec,
    *,
    store_full: bool = False,
    outputs: dict[str, str] | None = None,
    base: Product | None = None,
) -> RunDirectory:
    """A run directory of ``spec``: its units recorded, its large blocks regenerated.

    See :class:`~avrisk.pipeline.RunDirectory` for ``store_full``;
    ``outputs``: the units of outputs of ``f`` besides ``f`` [s] itself;
    ``base``: the ``P0`` its blocks are drawn again from (default the
    scenario's, with the shipped drivers' prior).
    """
    layout = param_layout(spec)
    units = {**layout.units(), "f": "s", **(outputs or {}), "log_p0": "log density"}
    return RunDirectory(
        out,
        layout.columns,
        units,
        base=base_distribution(spec) if base is None else base,
        store_full=store_full,
    )


@dataclass(frozen=True)
class EstimationResult:
    """Complete runs of one scenario and their report: what the API returns.

    Attributes
    ----------
    command : str
        ``"run"``, ``"compare"`` or ``"report"``: what made it.
    runs : list of (label, RunDirectory)
        The runs, the one under test first (then naive MC at its budget and
        the reference, for a comparison).
    spec : ScenarioSpec
        Their scenario.
    report : Path or None
        The HTML report written.
    ratios : list of dict or None
        A comparison's rows per threshold
        (:func:`~avrisk.api.document.ratio_rows`).
    has_reference : bool
        Whether a comparison has a naive reference run.
    """

    command: str
    runs: Runs
    spec: ScenarioSpec
    report: Path | None = None
    ratios: list[dict[str, Any]] | None = None
    has_reference: bool = False

    @property
    def estimate(self) -> dict[str, Any]:
        """The estimate of the run under test, as its ``summary.json`` holds it."""
        return self.runs[0][1].summary()["estimate"]

    @property
    def p(self) -> float:
        """``P0(f(X) <= gamma)`` at the run's main threshold."""
        return self.estimate["p"]

    @property
    def ci(self) -> tuple[float, float]:
        """The 95% interval of :attr:`p`."""
        low, high = self.estimate["ci"]
        return low, high

    @property
    def by_gamma(self) -> dict[float, float]:
        """``p`` at every threshold [s] of the run under test."""
        return {g["gamma"]: g["p"] for g in self.estimate["by_gamma"]}

    @property
    def path(self) -> Path:
        """The run directory of the run under test."""
        return self.runs[0][1].path

    def answer(self) -> Headline:
        """The answer, as the report and the command give it."""
        return answer(self.runs, self.spec)

    def document(self) -> dict[str, Any]:
        """Every figure, as ``--json`` prints it (schema ``avrisk.result/1``)."""
        return result_document(
            self.command, self.runs, self.spec, ratios=self.ratios, report=self.report
        )

    def __str__(self) -> str:
        return self.answer().sentence()


def scenario_spec(scenario: Scenario) -> ScenarioSpec:
    """A scenario given as a bundled name, a YAML path, a spec or its data."""
    if isinstance(scenario, ScenarioSpec):
        return scenario
    if isinstance(scenario, dict):
        return spec_from_dict(scenario)
    return load_spec(scenario)
