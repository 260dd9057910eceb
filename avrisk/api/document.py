"""The results of runs as data: the answer, the comparison, one JSON document.

:func:`result_document` is what ``avrisk run --json`` prints (schema
:data:`RESULT_SCHEMA`) and what :meth:`avrisk.api.EstimationResult.document`
returns; :func:`ratio_rows` compares a method with naive Monte Carlo at its
budget, per threshold.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from avrisk.pipeline import RunDirectory
from avrisk.rare.estimator import estimator_class
from avrisk.rare.results import jsonable
from avrisk.rare.trust import estimate_diagnostics
from avrisk.report.answer import Headline, headline, search_sentence, threshold_trust
from avrisk.report.plots import comparison_rows
from avrisk.scenario import ScenarioSpec

#: Schema of the ``--json`` document.
RESULT_SCHEMA = "avrisk.result/1"

#: Labelled runs, the one under test first.
Runs = list[tuple[str, RunDirectory]]


def answer(runs: Runs, spec: ScenarioSpec) -> Headline:
    """The answer of ``runs`` (the first one under test), as the report gives it."""
    return headline(
        [(label, d.summary()) for label, d in runs], spec.simulation.horizon
    )


def mechanisms(summary: dict[str, Any]) -> list[dict[str, Any]]:
    """``p`` by mechanism at the main threshold (empty when not recorded)."""
    gamma = summary["estimate"]["gamma"]
    return next(
        (
            m["by_label"]
            for m in (summary.get("mechanisms") or {}).get("by_gamma", [])
            if m["gamma"] == gamma
        ),
        [],
    )


def ratio_rows(
    tested: RunDirectory, naive: RunDirectory, reference: RunDirectory | None
) -> list[dict[str, Any]]:
    """The method against naive MC at its budget, per threshold, naive hits seen too.

    :func:`avrisk.report.plots.comparison_rows` (the report's) with
    ``naive_hits_seen``: the hits of the naive run at the same budget.
    """
    seen = {g["gamma"]: g["n_hits"] for g in naive.summary()["estimate"]["by_gamma"]}
    rows = comparison_rows(
        tested.summary()["estimate"],
        reference.summary()["estimate"] if reference is not None else None,
    )
    return [{**row, "naive_hits_seen": seen.get(row["gamma"])} for row in rows]


def result_document(
    command: str,
    runs: Runs,
    spec: ScenarioSpec,
    *,
    ratios: list[dict[str, Any]] | None = None,
    report: Path | None = None,
) -> dict[str, Any]:
    """The ``--json`` document: the answer, every run, the comparison, the report.

    Parameters
    ----------
    command : str
        ``"run"``, ``"compare"`` or ``"report"``.
    runs : list of (label, RunDirectory)
        Complete runs, the one under test first.
    spec : ScenarioSpec
        Their scenario (its name and horizon [s]).
    ratios : list of dict, optional
        :func:`ratio_rows` of a comparison.
    report : Path, optional
        The HTML report written.

    Returns
    -------
    dict
        Schema :data:`RESULT_SCHEMA`; non-finite numbers are ``null``. Keys
        ``answer`` (:meth:`Headline.to_dict`), ``runs`` (per run: ``label``,
        ``path``, ``method``, ``n_rollouts``, ``rollouts_reused`` from an
        earlier session, ``stopped_by``, ``search`` (whether the estimator's
        search converged at the main threshold,
        :meth:`~avrisk.rare.results.SearchConvergence.to_dict` and its
        ``sentence``; null for a method without one), ``by_gamma`` with
        ``trust`` and
        ``reasons`` per threshold, ``mechanisms`` at the main threshold,
        ``diagnostics``: the estimator's tables of the report, each
        :meth:`~avrisk.rare.estimator.DiagnosticTable.to_dict`),
        ``comparison`` (or null) and ``report`` (or null).
    """
    docs = []
    for label, run_dir in runs:
        summary = run_dir.summary()
        est = summary["estimate"]
        estimator = estimator_class(summary["method"])
        search = estimator.convergence(est, est["gamma"])
        by_gamma = []
        for g in sorted(est["by_gamma"], key=lambda g: g["gamma"]):
            trust = threshold_trust(summary, g)
            by_gamma.append(
                {
                    key: g.get(key)
                    for key in (
                        "gamma",
                        "p",
                        "stderr",
                        "ci",
                        "n_hits",
                        "ess",
                        "pareto_k",
                        "n_failed",
                        "p_if_failed_dangerous",
                        "interval",
                    )
                }
                | {"trust": trust.word, "reasons": list(trust.reasons)}
            )
        docs.append(
            {
                "label": label,
                "path": str(run_dir.path),
                "method": summary["method"],
                "n_rollouts": est["n_evals"],
                "rollouts_reused": summary["timing"]["rollouts_replayed"],
                "stopped_by": est.get("stopped_by", "budget"),
                "search": None
                if search is None
                else search.to_dict() | {"sentence": search_sentence(search)},
                "by_gamma": by_gamma,
                "mechanisms": mechanisms(summary),
                "diagnostics": [
                    t.to_dict() for t in estimate_diagnostics(estimator, est)
                ],
            }
        )
    doc = {
        "schema": RESULT_SCHEMA,
        "command": command,
        "scenario": spec.name,
        "horizon_s": spec.simulation.horizon,
        "answer": answer(runs, spec).to_dict(),
        "runs": docs,
        "comparison": ratios,
        "report": None if report is None else str(report),
    }
    return jsonable(doc)
