"""``avrisk ab``: is ego B at most a margin times as risky as ego A? A CI gate.

A thin shell over :func:`avrisk.compare_egos`: both egos drive the same draws
of the scenario, and the gate reads the one-sided 95% bounds of ``p_B /
p_A`` against ``--max-ratio``. The outcome is one line on stdout (or the
``--json`` document) and the exit status:

* 0 -- pass: the upper bound is at most the margin;
* 1 -- fail: the lower bound is above it;
* 3 -- inconclusive: neither (the line says about how many final-stage
  rollouts would likely decide it);
* 2 -- an error (one red line), 130 -- interrupted (resume by rerunning).

An ego is a registered policy name (``idm_mobil``, with its default
params, not the scenario's), an import path (``package.module:Class``), a
YAML or JSON file holding ``{policy: ..., params: {...}}``, or that mapping
inline (``'{policy: external, params:
{address: "tcp://127.0.0.1:5555"}}'`` for an external ZeroMQ server).
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer
import yaml

from avrisk.api.backends import DEFAULT_BACKEND
from avrisk.cli.backends import Address, BackendOption, Workers
from avrisk.cli.common import (
    CliError,
    Device,
    check_output_folder,
    err_console,
    resumable,
    user_errors,
)
from avrisk.cli.progress import RichProgress
from avrisk.cli.results import show_comparison
from avrisk.cli.run import Gamma, Scenario, Seed, Set, estimator_options
from avrisk.rare.paired import PAIRED_DEFAULTS, UNION_METHOD

#: The exit status of each outcome of the gate.
EXIT_CODES = {"pass": 0, "fail": 1, "inconclusive": 3}

EGO_FORMS = (
    "a registered policy name (its default params), an import path "
    "package.module:Class, a YAML/JSON file of {policy, params}, or that mapping "
    "inline"
)
EgoA = Annotated[
    str | None,
    typer.Option(
        help=f"The ego of reference (A): {EGO_FORMS}; default: the scenario's."
    ),
]
EgoB = Annotated[str, typer.Option("--ego-b", help=f"The new ego (B): {EGO_FORMS}.")]
NFinal = Annotated[
    int | None,
    typer.Option(
        min=1,
        help="Rollout pairs of the final stage "
        f"[default: {PAIRED_DEFAULTS['n_final']}].",
    ),
]
Json = Annotated[
    bool,
    typer.Option(
        "--json",
        help="Print the comparison as one JSON document on stdout (schema "
        "avrisk.ab/1) instead of the line; progress stays on stderr.",
    ),
]


def ego_option(value: str, flag: str) -> str | dict[str, Any]:
    """An ego as :func:`avrisk.compare_egos` takes it, from its option's text.

    Raises
    ------
    CliError
        For a file or mapping that is not a ``{policy, params}`` mapping.
    """
    path = Path(value)
    text = None
    if path.suffix in (".yaml", ".yml", ".json") and path.is_file():
        text = path.read_text()
    elif value.lstrip().startswith("{"):
        text = value
    if text is None:
        return value
    try:
        ego = yaml.safe_load(text)
    except yaml.YAMLError as err:
        raise CliError(f"{flag}: not YAML or JSON ({err.__class__.__name__})") from None
    if not isinstance(ego, dict) or "policy" not in ego:
        raise CliError(f"{flag} must hold a mapping with 'policy' (and 'params')")
    return ego


def ab(
    ctx: typer.Context,
    scenario: Scenario,
    ego_b: EgoB,
    ego_a: EgoA = None,
    max_ratio: Annotated[
        float,
        typer.Option(
            min=0.0, help="Largest acceptable p_B / p_A (1: B no riskier than A)."
        ),
    ] = 1.0,
    out: Annotated[
        Path, typer.Option("--out", help="Run directory (created or resumed).")
    ] = Path("runs/ab"),
    gamma: Gamma = 0.14,
    n_final: NFinal = None,
    seed: Seed = 0,
    batch_size: Annotated[
        int, typer.Option(min=1, help="Rollout pairs simulated together.")
    ] = 2048,
    set_: Set = None,
    failures: Annotated[
        int,
        typer.Option(
            min=0,
            help="Regressions and fixes the report animates, each with both egos on "
            "the same situation, the most realistic first.",
        ),
    ] = 3,
    device: Device = "cpu",
    workers: Workers = None,
    backend: BackendOption = DEFAULT_BACKEND,
    address: Address = None,
    as_json: Json = False,
) -> None:
    """Is ego B at most --max-ratio times as risky as ego A? Pass, fail or inconclusive.

    Both egos drive every draw of the scenario with the same seed; splitting
    + IS searches where either fails, and one weighted sample estimates p_A,
    p_B, their difference and ratio. Exit 0 when the one-sided upper 95%
    bound of p_B / p_A is at most --max-ratio, 1 when the lower one is above
    it, 3 otherwise (inconclusive); --ego-a defaults to the scenario's ego.
    Rerunning the same command resumes an interrupted comparison.
    """
    import avrisk
    from avrisk.api.runs import EXPECTED

    with user_errors(*EXPECTED), resumable(ctx):
        check_output_folder(out)
        options = estimator_options(
            UNION_METHOD, {"n_final": n_final}, set_, cli_defaults={}
        )
        result = avrisk.compare_egos(
            scenario,
            None if ego_a is None else ego_option(ego_a, "--ego-a"),
            ego_option(ego_b, "--ego-b"),
            out=out,
            max_ratio=max_ratio,
            gamma=gamma,
            seed=seed,
            batch_size=batch_size,
            failures=failures,
            device=device,
            workers=workers,
            backend=backend,
            address=address,
            progress=RichProgress(err_console),
            **options,
        )
    show_comparison(result, as_json)
    raise typer.Exit(code=EXIT_CODES[result.verdict.outcome])
