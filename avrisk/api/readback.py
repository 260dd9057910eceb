"""Files read back from disk, checked before use: one clear line if damaged.

``report``, ``replay`` and a rerun of ``run`` read files that a person may have
edited, truncated or swapped: a run's ``config.json`` and ``summary.json``, a
samples table and the scenario stored in its metadata. Each is checked here
for what the commands then rely on (valid JSON without NaN, the fields and
types used, readable Parquet with numeric columns, rows inside the scenario's
ranges), and refused with a :class:`~avrisk.api.errors.UserError` naming the
file and the problem; never a traceback, never used as if it were sound.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from avrisk.api.errors import UserError
from avrisk.pipeline.layout import CONFIG_FILE, SUMMARY_FILE
from avrisk.pipeline.regenerate import META_KEY
from avrisk.scenario import ScenarioSpec
from avrisk.scenario.errors import clip

_DAMAGED = "was it edited or damaged? rerun the command that made it"


def _no_constant(name: str) -> float:
    raise ValueError(f"{name} is not a number JSON allows")


def parse_json(text: str | bytes, source: str) -> Any:
    """``text`` as JSON (``NaN`` and ``Infinity`` refused), or a UserError."""
    try:
        return json.loads(text, parse_constant=_no_constant)
    except json.JSONDecodeError as exc:
        raise UserError(
            f"{source}: not valid JSON ({exc.msg}, line {exc.lineno}); {_DAMAGED}"
        ) from None
    except (ValueError, UnicodeDecodeError, RecursionError) as exc:
        raise UserError(f"{source}: not valid JSON ({exc}); {_DAMAGED}") from None


def read_json(path: Path) -> dict[str, Any]:
    """The JSON object in ``path``, or a UserError naming the file."""
    try:
        text = path.read_bytes()
    except OSError as exc:
        raise UserError(f"{path}: cannot be read: {exc.strerror or exc}") from None
    data = parse_json(text, str(path))
    if not isinstance(data, dict):
        raise UserError(
            f"{path}: holds a JSON {type(data).__name__}, not an object; {_DAMAGED}"
        )
    return data


def read_config(run_dir: Path) -> dict[str, Any]:
    """A run's ``config.json``: an object holding its scenario and settings."""
    path = run_dir / CONFIG_FILE
    config = read_json(path)
    for key in ("scenario", "settings"):
        if not isinstance(config.get(key), dict):
            raise UserError(
                f"{path}: holds no '{key}' section, so it is not the config of an "
                f"avrisk run; {_DAMAGED}"
            )
    return config


Number = float  # NaN and infinities are refused by parse_json already


class _GammaFigures(BaseModel):
    """What a summary records at one threshold, as an estimate or a test threshold."""

    model_config = ConfigDict(extra="allow")

    gamma: Number
    p: Number = Field(ge=0.0)
    stderr: Number = Field(ge=0.0)
    ci: tuple[Number, Number]
    n_hits: int = Field(ge=0)


class _Threshold(_GammaFigures):
    ess: Number | None = None


class _Estimate(_GammaFigures):
    n_evals: int = Field(ge=0)
    by_gamma: list[_Threshold] = Field(min_length=1)


class _Summary(BaseModel):
    model_config = ConfigDict(extra="allow")

    estimate: _Estimate
    settings: dict[str, Any]
    versions: dict[str, Any]


def check_summary(run_dir: Path) -> None:
    """Refuse a ``summary.json`` that is not what avrisk writes (shape, types)."""
    path = run_dir / SUMMARY_FILE
    summary = read_json(path)
    try:
        checked = _Summary.model_validate(summary, strict=False)
    except ValidationError as exc:
        err = exc.errors(include_url=False)[0]
        where = ".".join(str(p) for p in err["loc"]) or "(top level)"
        raise UserError(
            f"{path}: not an avrisk summary ({where}: {err['msg']}); {_DAMAGED}"
        ) from None
    est = checked.estimate
    if all(g.gamma != est.gamma for g in est.by_gamma):
        raise UserError(
            f"{path}: not an avrisk summary (no estimate at its own threshold "
            f"{est.gamma:g}); {_DAMAGED}"
        )


def check_recorded(run_dir: Path) -> None:
    """Check the JSON records of a run directory, those it holds, before use."""
    if (run_dir / CONFIG_FILE).is_file():
        read_config(run_dir)
    if (run_dir / SUMMARY_FILE).is_file():
        check_summary(run_dir)


def read_schema(path: Path) -> pa.Schema:
    """The schema of Parquet file ``path``, or a UserError naming the file."""
    try:
        return pq.read_schema(path)
    except (pa.ArrowException, OSError) as exc:
        raise UserError(
            f"{path}: not a readable Parquet file ({clip(str(exc), 120)})"
        ) from None


def read_table(path: Path) -> pa.Table:
    """The Parquet table in ``path``, or a UserError naming the file."""
    try:
        return pq.read_table(path)
    except (pa.ArrowException, OSError) as exc:
        raise UserError(
            f"{path}: not a readable Parquet file ({clip(str(exc), 120)})"
        ) from None


def check_columns(
    schema: pa.Schema,
    path: Path,
    numeric: Sequence[str],
    integer: Sequence[str] = (),
) -> None:
    """Refuse a table lacking a column, or with a non-numeric one."""
    missing = [c for c in (*numeric, *integer) if c not in schema.names]
    if missing:
        raise UserError(
            f"{path}: lacks column(s) {missing[:4]}"
            + (f" and {len(missing) - 4} more" if len(missing) > 4 else "")
            + f"; {_DAMAGED}"
        )
    for name in numeric:
        kind = schema.field(name).type
        if not (pa.types.is_floating(kind) or pa.types.is_integer(kind)):
            raise UserError(f"{path}: column {name!r} holds {kind}, not numbers")
    for name in integer:
        kind = schema.field(name).type
        if not pa.types.is_integer(kind):
            raise UserError(f"{path}: column {name!r} holds {kind}, not integers")


def stored_params(schema: pa.Schema, params: Sequence[str]) -> list[str]:
    """The parameters a samples table must hold: all, but for those it left out.

    A run's table may leave out large blocks of ``X`` (they are drawn again,
    checked, on reading: :mod:`avrisk.pipeline.regenerate`).
    """
    if META_KEY not in (schema.metadata or {}):
        return list(params)
    return [p for p in params if p in schema.names]


def check_samples(path: Path, params: Sequence[str]) -> None:
    """Refuse a run's samples table that a report cannot read or trust."""
    if not path.is_file():
        raise UserError(f"{path}: missing; {_DAMAGED}")
    schema = read_schema(path)
    required = (*stored_params(schema, params), "f", "weight", "log_p0")
    check_columns(schema, path, required, ("seed",))


_VEHICLE_COLUMN = re.compile(r"^veh(\d+)\.(\w+)$")


def check_rows(
    spec: ScenarioSpec,
    columns: Sequence[str],
    x: np.ndarray,
    rows: Sequence[int],
    path: Path,
) -> None:
    """Refuse rows of ``x`` with a non-finite value or one outside its range.

    A vehicle coordinate (``veh<j>.<field>``) must lie in the support
    ``[lo, lo + scale]`` of its marginal in ``spec``; any other coordinate
    (``xi``) must be finite.
    """
    for i, row in zip(rows, x, strict=True):
        for name, value in zip(columns, row, strict=True):
            value = float(value)
            if not math.isfinite(value):
                raise UserError(f"{path}: row {i}: {name} is {value}, not a number")
            found = _VEHICLE_COLUMN.match(name)
            if found is None or int(found[1]) >= spec.n_vehicles:
                continue
            marginal = getattr(spec.initial_for(int(found[1])), found[2], None)
            if marginal is None:
                continue
            slack = 1e-6 * marginal.scale
            if not marginal.lo - slack <= value <= marginal.hi + slack:
                raise UserError(
                    f"{path}: row {i}: {name} = {value:g} lies outside its range "
                    f"[{marginal.lo:g}, {marginal.hi:g}] in scenario "
                    f"{spec.name!r}; {_DAMAGED}"
                )
