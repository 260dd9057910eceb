"""Validation errors of a scenario spec, worded for a person.

:func:`format_validation_error` turns Pydantic's errors into one line per
problem, ``field.path: what is wrong (got value)``, and suggests the closest
field name for an unknown key.
"""

from __future__ import annotations

import difflib
import types
import typing
from collections.abc import Mapping
from typing import Any

from pydantic import BaseModel, ValidationError

from avrisk.scenario.spec import ScenarioSpec


class ScenarioSpecError(ValueError):
    """A scenario file could not be found, read or validated.

    The message is meant for a person: it names the file, each bad field, the
    allowed values and what was given.
    """


def format_validation_error(exc: ValidationError, source: str) -> str:
    """One line per problem: ``field.path: what is wrong (got value)``.

    Parameters
    ----------
    exc : pydantic.ValidationError
    source : str
        The file or name being validated.

    Returns
    -------
    str
    """
    lines = [f"{source}: invalid scenario:"]
    for err in exc.errors(include_url=False):
        loc = ".".join(clip(str(p), 40) for p in err["loc"])
        msg = err["msg"].removeprefix("Value error, ")
        if err["type"] == "extra_forbidden":
            msg = _unknown_field_message(err["loc"])
        elif err["type"] == "missing":
            msg = "required field is missing"
        got = err.get("input")
        show_got = err["type"] not in {"missing", "value_error", "assertion_error"}
        if show_got and not isinstance(got, Mapping | list):
            msg = f"{msg} (got {clip(repr(got), 60)})"
        if not loc:
            # Cross-field problems name their own fields, one per line.
            lines.extend(f"  {line}" for line in msg.splitlines())
        else:
            lines.append(f"  {loc}: {msg}")
    return "\n".join(clip(line, MAX_LINE) for line in lines)


#: Longest line of an error message; a longer one (a huge value echoed back)
#: is cut, saying by how much.
MAX_LINE = 300


def clip(text: str, limit: int = MAX_LINE) -> str:
    """``text`` cut to about ``limit`` characters, saying how many were left out.

    Examples
    --------
    >>> clip("a" * 1000, 20)
    'aaaaaaaaaaaaaaaaaaaa... (980 more characters)'
    """
    if len(text) <= limit:
        return text
    return f"{text[:limit]}... ({len(text) - limit:,} more characters)"


def _unknown_field_message(loc: tuple[int | str, ...]) -> str:
    """Explain an unknown key, suggesting the closest allowed field names."""
    model: Any = ScenarioSpec
    for part in loc[:-1]:
        model = _field_type(model, part)
    models = [m for m in _union_members(model) if _is_model(m)]
    allowed = sorted(models[0].model_fields) if models else []
    close = difflib.get_close_matches(str(loc[-1]), allowed, n=1)
    hint = f"did you mean {close[0]!r}? " if close else ""
    return f"unknown field; {hint}allowed here: {', '.join(allowed)}"


def _is_model(tp: Any) -> bool:
    return isinstance(tp, type) and issubclass(tp, BaseModel)


def _union_members(tp: Any) -> tuple[Any, ...]:
    if typing.get_origin(tp) in (typing.Union, types.UnionType):
        return typing.get_args(tp)
    return (tp,)


def _field_type(tp: Any, part: int | str) -> Any:
    """Type reached from ``tp`` by one step of a validation-error location."""
    # Unwrap Optional[...] / X | None to the model inside.
    for arg in _union_members(tp):
        if _is_model(arg) and isinstance(part, str) and part in arg.model_fields:
            return arg.model_fields[part].annotation
        origin = typing.get_origin(arg)
        if origin in (tuple, list) and isinstance(part, int):
            return typing.get_args(arg)[0]
        if origin is dict and isinstance(part, str):
            return typing.get_args(arg)[1]
    return None
