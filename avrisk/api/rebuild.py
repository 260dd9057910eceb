"""Reports written again from a run directory alone (``avrisk report DIR``).

:func:`rebuild` tells a directory's kind by what its ``config.json``
records, never by importing anything from it: a run of two egos (``ego_a``
and ``ego_b``, what ``avrisk ab`` records) gets its ``ab_report.html`` and
``ab.json`` written again by the function ``avrisk ab`` writes them with
(:func:`avrisk.api.ab.conclude`); any other directory, a run or a
comparison of methods, its ``report.html``
(:func:`avrisk.api.reports.rebuild_report`, whose checks refuse a directory
that is neither).
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from avrisk.api.ab import AB_FILE, AB_SCHEMA, PAIR_UNITS, ABResult, conclude
from avrisk.api.errors import UserError
from avrisk.api.readback import (
    check_columns,
    check_recorded,
    check_samples,
    read_config,
    read_json,
    read_schema,
)
from avrisk.api.reports import rebuild_report
from avrisk.api.result import EstimationResult, Scenario, samples_directory
from avrisk.assembly import MECHANISMS, ScenarioSimulator, param_layout
from avrisk.pipeline.layout import SAMPLES_FILE
from avrisk.rare.paired import PAIR_COLUMNS
from avrisk.rare.problem import STATUS
from avrisk.scenario import ScenarioSpec, spec_from_dict

__all__ = ["rebuild", "rebuild_ab_report", "records_two_egos"]

#: The config's records of the two egos of an A/B comparison.
EGO_KEYS = ("ego_a", "ego_b")
#: Regressions and fixes animated where ``ab.json`` does not say (one written
#: before it recorded ``animated``): ``avrisk ab``'s default.
DEFAULT_ANIMATED = 3
#: The report's failures of a run or comparison of methods, by default.
DEFAULT_FAILURES = 6


def rebuild(
    run_dir: Path,
    failures: int | None = None,
    scenario: Scenario | None = None,
    device: str = "cpu",
) -> EstimationResult | ABResult:
    """The report of a finished run, comparison or A/B comparison, written again.

    ``failures``: the failures the report animates (default 6), or for an
    A/B comparison the regressions and fixes, each (default: as many as
    ``avrisk ab`` animated). ``scenario``: a run's scenario given again
    (:func:`~avrisk.api.reports.rebuild_report`); refused for an A/B
    comparison.
    """
    if not records_two_egos(run_dir):
        chosen = DEFAULT_FAILURES if failures is None else failures
        return rebuild_report(run_dir, chosen, scenario, device)
    if scenario is not None:
        raise UserError(
            f"{run_dir} is an A/B comparison: its scenario is not given again; "
            "to animate egos that name user code, rerun its avrisk ab command"
        )
    return rebuild_ab_report(run_dir, failures, device)


def records_two_egos(run_dir: Path) -> bool:
    """Whether ``run_dir/config.json`` records two egos, as ``avrisk ab`` does.

    A config that cannot be read says no: the checks of a run's report then
    name what is wrong with it.
    """
    try:
        config = read_config(run_dir)
    except UserError:
        return False
    return all(key in config for key in EGO_KEYS)


class _Verdict(BaseModel):
    model_config = ConfigDict(extra="allow")

    max_ratio: float = Field(ge=0.0, allow_inf_nan=False)


class _Recorded(BaseModel):
    """What a rebuilt report takes from ``ab.json``: the margin, the animated."""

    model_config = ConfigDict(extra="allow")

    schema_: str = Field(alias="schema", pattern=f"^{re.escape(AB_SCHEMA)}$")
    verdict: _Verdict
    animated: int = Field(DEFAULT_ANIMATED, ge=0)


def rebuild_ab_report(
    run_dir: Path, failures: int | None = None, device: str = "cpu"
) -> ABResult:
    """``ab.json`` and ``ab_report.html`` of a finished A/B comparison, again.

    The paired estimate and the discordant rollouts come from the records
    (every one checked before use), the gate's margin from ``ab.json``;
    ``failures``: the regressions and fixes animated, each (default: as many
    as ``avrisk ab`` animated). Animations already made are kept; one that
    is missing is made again where its ego names no user code (the directory
    alone never makes avrisk import code), else left out.
    """
    check_recorded(run_dir)
    config = read_config(run_dir)
    specs = _ego_specs(run_dir, config)
    directory = samples_directory(run_dir, specs[0], outputs=PAIR_UNITS)
    if not directory.is_complete:
        raise UserError(f"{run_dir} is not finished; rerun its command to resume it")
    recorded = _recorded(run_dir)
    samples = directory.path / SAMPLES_FILE
    check_samples(samples, param_layout(specs[0]).columns)
    column = MECHANISMS[0]
    numeric = [*PAIR_COLUMNS, "log_weight", f"{column}_a", f"{column}_b"]
    check_columns(read_schema(samples), samples, numeric, ("stage", STATUS))
    simulators = tuple(
        None if spec.import_paths() else ScenarioSimulator(spec, device=device)
        for spec in specs
    )
    return conclude(
        directory,
        specs,
        directory.summary()["estimate"],
        recorded.verdict.max_ratio,
        recorded.animated if failures is None else failures,
        (simulators[0], simulators[1]),
    )


def _ego_specs(
    run_dir: Path, config: dict[str, Any]
) -> tuple[ScenarioSpec, ScenarioSpec]:
    """The scenario with ego A (as recorded) and with ego B (its ``ego_b``)."""
    source = f"{run_dir}/config.json"
    spec_a = spec_from_dict(config["scenario"], source=source)
    data = spec_a.model_dump(mode="json")
    data["ego"] = config["ego_b"]
    return spec_a, spec_from_dict(data, source=f"{source} (ego_b)")


def _recorded(run_dir: Path) -> _Recorded:
    """The margin and the count animated that ``ab.json`` records, checked."""
    path = run_dir / AB_FILE
    if not path.is_file():
        raise UserError(
            f"{path}: missing; rerun the avrisk ab command that made {run_dir}: it "
            "reads the finished comparison back and writes it and the report"
        )
    try:
        return _Recorded.model_validate(read_json(path))
    except ValidationError as exc:
        err = exc.errors(include_url=False)[0]
        where = ".".join(str(p) for p in err["loc"]) or "(top level)"
        raise UserError(
            f"{path}: not an A/B record ({where}: {err['msg']}); was it edited or "
            "damaged? rerun the avrisk ab command that made it"
        ) from None
