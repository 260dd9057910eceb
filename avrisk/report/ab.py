"""The HTML report of an A/B comparison of two egos (``avrisk ab``).

The verdict and the paired estimates first, then B's regressions (the
situations B fails in and A does not), the most realistic first, each with
its failure mechanism and the two egos side by side on the same situation,
then B's fixes the same way.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import jinja2

from avrisk.pipeline.files import write_atomic

__all__ = ["AB_REPORT_FILE", "write_ab_report"]

#: The report, in the run directory.
AB_REPORT_FILE = "ab_report.html"

#: Each kind of discordant rollout: its section's title and note.
KINDS = {
    "regressions": (
        "B's regressions: B fails, A does not",
        "Situations the search sampled in which B comes within the threshold and A "
        "does not, the most realistic first (ranked by the lower of the start's and "
        "the drivers' percentiles under P0); the mechanism is B's.",
    ),
    "fixes": (
        "B's fixes: A fails, B does not",
        "The reverse, ranked the same way; the mechanism is A's.",
    ),
}


def write_ab_report(
    out: Path,
    document: Mapping[str, Any],
    discordant: Mapping[str, list[dict[str, Any]]],
) -> Path:
    """Write ``out/ab_report.html``; its path.

    Parameters
    ----------
    out : Path
        The run directory (animations are referred to relative to it).
    document : mapping
        The comparison's document (``ab.json``).
    discordant : mapping
        ``"regressions"`` and ``"fixes"``: rows with ``mechanism``,
        ``percentile``, ``f_a``, ``f_b``, ``seed`` and the two animations'
        paths (``animation_a``, ``animation_b``, relative to ``out``, or None).
    """
    paired = document["paired"]
    quantities = [
        ("p_A", {**paired["a"], "value": paired["a"]["p"]}),
        ("p_B", {**paired["b"], "value": paired["b"]["p"]}),
        ("p_B - p_A", paired["difference"]),
        ("p_B / p_A", paired["ratio"]),
        (
            "P(B fails, A does not)",
            {**paired["regressions"], "value": paired["regressions"]["p"]},
        ),
        ("P(A fails, B does not)", {**paired["fixes"], "value": paired["fixes"]["p"]}),
    ]
    kinds = [
        {"title": title, "note": note, "rows": discordant.get(kind, [])}
        for kind, (title, note) in KINDS.items()
    ]
    env = jinja2.Environment(
        loader=jinja2.PackageLoader("avrisk.report", "templates"),
        autoescape=jinja2.select_autoescape(["html", "j2"]),
    )
    html = env.get_template("ab.html.j2").render(
        doc=document, quantities=quantities, kinds=kinds
    )
    path = out / AB_REPORT_FILE
    write_atomic(path, html)
    return path
