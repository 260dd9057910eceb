"""The estimators' settings as command-line options, checked by name.

A setting with a flag (``--rho``, ``--n-iter`` ...; :data:`ESTIMATOR_FLAGS`)
shows each method's default in its help (:func:`setting_option`); any setting
comes by ``--set NAME=VALUE``. A setting the chosen method does not have is
refused in one line naming the methods that have it, or the closest setting
(:func:`foreign`).
"""

from __future__ import annotations

import difflib
from typing import Annotated, Any

import typer
import yaml

from avrisk.cli.common import CliError
from avrisk.rare import estimator_names
from avrisk.rare.estimator import DEFAULT_METHOD, estimator_class

__all__ = [
    "CLI_DEFAULTS",
    "ESTIMATOR_FLAGS",
    "estimator_options",
    "foreign",
    "methods_with",
    "setting_option",
]

#: Where the command line's defaults differ from an estimator's own.
CLI_DEFAULTS = {"n_iter": 20}


def methods_with(name: str) -> list[str]:
    """The registered estimators that have the setting ``name``."""
    return [
        m for m in estimator_names() if name in estimator_class(m).Settings.model_fields
    ]


def _defaults(name: str, cli_defaults: dict[str, Any]) -> str:
    """``"10000 for splitting_is; 100000 for ce, defensive, mixture, naive"``.

    The default of setting ``name`` per estimator that has it (the command's
    ``cli_defaults`` over the estimator's own), the default method first.
    """
    by_value: dict[str, list[str]] = {}
    owners = methods_with(name)
    for m in sorted(owners, key=lambda m: m != DEFAULT_METHOD):
        value = cli_defaults.get(
            name, estimator_class(m).Settings.model_fields[name].default
        )
        by_value.setdefault(str(value), []).append(m)
    if len(by_value) == 1 and len(owners) == len(estimator_names()):
        return next(iter(by_value))
    return "; ".join(f"{v} for {', '.join(ms)}" for v, ms in by_value.items())


def setting_option(
    kind: type, name: str, text: str, cli_defaults: dict[str, Any] = CLI_DEFAULTS
) -> Any:
    """An estimator-setting option (``kind | None``): its help gives each default.

    ``text`` says what it is; the help adds, per method that has the setting,
    its default, so a flag of another method's (``--rho`` with splitting_is)
    shows as such.
    """
    option = typer.Option(help=f"{text} [default: {_defaults(name, cli_defaults)}].")
    return Annotated[kind | None, option]


def estimator_options(
    method: str,
    flags: dict[str, Any],
    assignments: list[str] | None,
    cli_defaults: dict[str, Any] = CLI_DEFAULTS,
) -> dict[str, Any]:
    """The estimator's settings from its flags and ``--set NAME=VALUE``.

    Flags left unset take the command's defaults (``cli_defaults``, those of
    the estimator's settings that it has) or else the estimator's own; a
    flag or name the estimator does not have is a CliError (:func:`foreign`).
    """
    try:
        known = estimator_class(method).Settings.model_fields
    except KeyError as err:
        raise CliError(
            f"method must be one of {estimator_names()}; got {method!r}"
        ) from err
    given = {k: v for k, v in flags.items() if v is not None}
    flagged = set(given)
    for text in assignments or []:
        name, sep, value = text.partition("=")
        if not sep or not name.strip():
            raise CliError(f"--set takes NAME=VALUE; got {text!r}")
        given[name.strip()] = yaml.safe_load(value)
        flagged.discard(name.strip())
    unknown = sorted(set(given) - set(known))
    if unknown:
        raise CliError(foreign(method, unknown, flagged))
    defaults = {k: v for k, v in cli_defaults.items() if k in known}
    return {**defaults, **given}


def foreign(method: str, names: list[str], flag_names: set[str]) -> str:
    """The one-line error for settings ``names`` that ``method`` does not have.

    Each is named as given (a flag of ``flag_names`` as ``--n-iter``) with
    the methods that have it, then the method's own settings: ``--rho: not a
    setting of method 'splitting_is', the default (--rho belongs to ce,
    defensive, mixture: choose one with --method); its settings: ...``. A
    name no method has is answered with the closest setting, the method's own
    first: ``n_particle: ... (did you mean n_particles?)``.
    """
    shown = {n: f"--{n.replace('_', '-')}" if n in flag_names else n for n in names}
    known = estimator_class(method).Settings.model_fields
    owners: dict[str, list[str]] = {}
    misspelt = []
    for name in names:
        methods = methods_with(name)
        if methods:
            owners.setdefault(", ".join(methods), []).append(shown[name])
        else:
            misspelt.append(_closest_setting(name, list(known)))
    whose = "; ".join(
        f"{', '.join(given)} {'belongs' if len(given) == 1 else 'belong'} to {methods}"
        for methods, given in owners.items()
    )
    reasons = [f"{whose}: choose one with --method"] if owners else []
    default = ", the default" if method == DEFAULT_METHOD else ""
    return (
        f"{', '.join(shown.values())}: not "
        f"{'a setting' if len(names) == 1 else 'settings'} of method "
        f"{method!r}{default} ({'; '.join(reasons + misspelt)}); its settings: "
        f"{', '.join(known)}"
    )


def _closest_setting(name: str, own: list[str]) -> str:
    """``"did you mean n_particles?"`` for a ``name`` no estimator has.

    The closest of the method's ``own`` settings, else of every estimator's
    (saying whose), else that no method has it.
    """
    close = difflib.get_close_matches(name, own, n=1)
    if close:
        return f"did you mean {close[0]}?"
    every = {
        s for m in estimator_names() for s in estimator_class(m).Settings.model_fields
    }
    close = difflib.get_close_matches(name, sorted(every), n=1)
    if close:
        return (
            f"did you mean {close[0]}, a setting of "
            f"{', '.join(methods_with(close[0]))}? choose one with --method"
        )
    return f"{name} is no method's setting"


#: The options of ``run`` and ``compare`` that are estimator settings by name.
ESTIMATOR_FLAGS = (
    "rho",
    "alpha",
    "n_per_iter",
    "n_iter",
    "n_final",
    "select",
    "defensive",
)
