"""The report tables of ``splitting_is`` after its levels'.

:meth:`SplittingImportanceSampling.diagnostics
<avrisk.rare.splitting_importance.SplittingImportanceSampling.diagnostics>`
shows subset simulation's tables of the levels, then these two: the proposal
fitted to the particles with its sample's diagnostics at ``gamma``
(:func:`proposal_table`), and, per threshold, the importance-sampling
estimate beside the levels' own of the same run (:func:`cross_check_table`).
"""

from __future__ import annotations

from typing import Any

from avrisk.rare.estimator import DiagnosticTable

__all__ = ["cross_check_table", "importance_sampling_tables", "proposal_table"]


def importance_sampling_tables(estimate: dict[str, Any]) -> list[DiagnosticTable]:
    """The proposal's table and the cross-check, from a run's ``details``.

    Parameters
    ----------
    estimate : dict
        An :class:`~avrisk.rare.results.Estimate` as a dict whose ``details``
        hold the levels' estimates (``details["splitting"]``).
    """
    details = estimate["details"]
    by_gamma = sorted(estimate["by_gamma"], key=lambda g: g["gamma"])
    sampled = details.get("importance_sampling")
    if sampled:  # the sample's own estimates, whichever is the answer
        by_gamma = [{**g, **sampled[str(g["gamma"])]} for g in by_gamma]
    main = next(g for g in by_gamma if g["gamma"] == estimate["gamma"])
    return [proposal_table(details, main), cross_check_table(details, by_gamma)]


def cross_check_table(
    details: dict[str, Any], by_gamma: list[dict[str, Any]]
) -> DiagnosticTable:
    """Per threshold, the importance sample's estimate beside the levels'."""
    own = [details["splitting"].get(str(g["gamma"]), {}) for g in by_gamma]
    return DiagnosticTable(
        "Importance sampling vs subset simulation's own estimate",
        ("gamma", "p", "95% CI", "p, subset simulation", "its 95% CI"),
        [
            (g["gamma"], g["p"], g["ci"], s.get("p"), s.get("ci"))
            for g, s in zip(by_gamma, own, strict=True)
        ],
        note=(
            "A cross-check from the same run: importance sampling beside "
            "the product of the levels' shares. The two are not "
            "independent (the levels made the proposal) but err "
            "differently: intervals far apart say one of them missed part "
            "of the event. "
            + (
                "The answer is the levels' product: before the final "
                "samples were drawn, the particles predicted them further "
                "from p (the proposal cannot hold everything the levels "
                "found)."
                if details.get("answer") == "splitting"
                else "The answer is importance sampling's."
            )
            + _added_note(details)
        ),
    )


def _added_note(details: dict[str, Any]) -> str:
    """What the replicates added after the fit were for, if any were."""
    added = details.get("replicates_added")
    if not added:
        return ""
    return (
        f" The levels' product is the mean of {len(details['replicates'])} "
        f"replicates, {added} of them run after the fit: the levels were to "
        "answer, and their interval was wider than a factor of 2 at three "
        "standard errors (avrisk.rare.splitting_precision)."
    )


def shift_kind(details: dict[str, Any]) -> str:
    """``"slope"``, ``"coords+var"`` or ``"coords"``: how the proposal moves P0."""
    if details.get("along_slope"):
        return "slope"
    return "coords+var" if details.get("fitted_variances") else "coords"


def proposal_table(details: dict[str, Any], main: dict[str, Any]) -> DiagnosticTable:
    """The fitted proposal's choices and its sample's diagnostics at ``gamma``."""
    fit = (
        details["n_components"],
        shift_kind(details),
        details["n_shifted"],
        details["informative_threshold"],
        details["fit_acceptance"],
        main["n_hits"],
        main["ess"],
        main["pareto_k"],
    )
    columns = ("components", "shift", "shifted coordinates", "threshold [SE]")
    columns += ("acceptance at gamma", "hits", "ESS", "Pareto k")
    return DiagnosticTable(
        "Importance-sampling proposal",
        columns,
        [fit],
        note=(
            "The distribution the final samples were drawn from, fitted "
            "to the dangerous samples the levels found (moved once more, "
            "at gamma, after the last set: the moves at gamma): its components "
            "(regions), its shift (coords: coordinate by coordinate; "
            "coords+var: the same with each coordinate's variance fitted "
            "too; slope: along f's average slope), how many of P0's "
            "coordinates it shifts (those the dangerous samples differ "
            "on by more than the threshold, in standard errors; the rest "
            "stay as in P0), and the share of moves accepted at gamma "
            "when those samples were made. Hits, ESS and Pareto k are "
            "its samples' at gamma."
        ),
    )
