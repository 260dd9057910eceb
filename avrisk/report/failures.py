"""A dangerous rollout as a failure card of the report shows it.

Each parameter with its unit; with the scenario at hand, the vehicles' start
at absolute positions (``x`` [m] along the road, ``y`` [m] from its right
edge, as the simulator places them: :func:`avrisk.assembly.initial_state`) and
the rollout's ``log p0`` read as a percentile: the share of situations drawn
from P0 that are less likely than this one.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import torch
from numpy.typing import NDArray

from avrisk.assembly import MECHANISMS, base_distribution, initial_state
from avrisk.scenario import ScenarioSpec
from avrisk.scenario.params import XI_PREFIX, ParamLayout, ScenarioParams

#: Situations drawn from P0 to read a ``log p0`` as a percentile.
P0_SAMPLE_SIZE = 10_000


def p0_log_density_sample(
    spec: ScenarioSpec, n: int = P0_SAMPLE_SIZE, seed: int = 0
) -> NDArray[np.float64]:
    """``log p0(X)`` of ``n`` situations ``X ~ P0``, sorted.

    Returns
    -------
    ndarray of shape (n,)
        Ascending log-densities (the reference for :func:`p0_percentile`).
    """
    base = base_distribution(spec)
    return np.sort(base.log_prob(base.sample(n, np.random.default_rng(seed))))


def p0_percentile(log_p0: float, sample: NDArray[np.float64]) -> float:
    """Percent of ``sample`` (sorted ``log p0`` of P0 draws) below ``log_p0``."""
    return 100.0 * np.searchsorted(sample, log_p0, side="left") / sample.size


def vehicle_starts(row: Mapping[str, Any], spec: ScenarioSpec) -> list[dict[str, Any]]:
    """The vehicles of a samples-table row at the start, in absolute terms.

    Parameters
    ----------
    row : mapping
        Holds ``veh<j>.s``, ``.t``, ``.heading``, ``.speed`` for every slot.
    spec : ScenarioSpec

    Returns
    -------
    list of dict
        One per vehicle, the ego first: ``name``, ``driver`` (its type or
        policy), ``lane`` (its slot's, 0 = rightmost), ``x`` [m] along the
        road, ``y`` [m] from the right road edge, ``heading`` [deg] from the
        lane direction (ccw > 0), ``speed`` [m/s].
    """
    layout = ParamLayout(spec.n_vehicles)  # the vehicles' columns; xi unused
    params = ScenarioParams.from_columns({c: [row[c]] for c in layout.columns}, layout)
    state = initial_state(params, spec, dtype=torch.float64)
    out = []
    for j, slot in enumerate(spec.vehicles):
        out.append(
            {
                "name": "ego" if j == 0 else f"vehicle {j}",
                "driver": spec.ego.policy if j == 0 else _driver_name(spec, j),
                "lane": slot.lane,
                "x": float(state.x[0, j]),
                "y": float(state.y[0, j]),
                "heading": float(params.heading[0, j]),
                "speed": float(params.speed[0, j]),
            }
        )
    return out


def _driver_name(spec: ScenarioSpec, slot: int) -> str:
    name = spec.vehicles[slot].driver
    return name if name is not None else next(iter(spec.drivers))


def failure_view(
    row: Mapping[str, Any],
    spec: ScenarioSpec | None,
    p0_sample: NDArray[np.float64] | None,
    *,
    names: Sequence[str],
    units: Mapping[str, str],
    animation: str | None,
) -> dict[str, Any]:
    """What the report's card of one failure shows.

    Parameters
    ----------
    row : mapping
        The rollout's samples-table row.
    spec : ScenarioSpec or None
        Its scenario: vehicles listed at absolute positions (else ``names``
        as recorded, each with its unit from ``units``).
    p0_sample : ndarray or None
        From :func:`p0_log_density_sample`, to give ``log p0`` a percentile.
    names : sequence of str
        The rollout's parameters, by column name.
    units : mapping of str to str
        Unit of each column, as the run directory records them.
    animation : str or None
        Path of its animation, relative to the report.

    Returns
    -------
    dict
        ``f`` [s], ``crash``, ``what`` (mechanism and vehicle hit, or None),
        ``log_p0``, ``percentile`` (or None), ``phase``, ``iteration``,
        ``sample_id``, ``vehicles`` (:func:`vehicle_starts`, or empty),
        ``params`` (text of the parameters not in ``vehicles``) and
        ``animation``.
    """
    vehicles = vehicle_starts(row, spec) if spec is not None else []
    shown = [n for n in names if isinstance(row.get(n), float)]
    if vehicles:
        shown = [n for n in shown if not n.startswith("veh")]
    # The driver network's hundreds of weights are no reading for a person.
    n_xi = sum(n.startswith(XI_PREFIX) for n in shown)
    params = ", ".join(
        f"{n} = {row[n]:.3g}" + (f" {units[n]}" if units.get(n) else "")
        for n in shown
        if not n.startswith(XI_PREFIX)
    )
    if n_xi:
        params += (", " if params else "") + (
            f"{n_xi} driver-network weights {XI_PREFIX}* (drawn with the rest of X)"
        )
    contact, hit = row.get("contact"), row.get("collision_with")
    what = [MECHANISMS[1].get(int(contact), "")] if contact is not None else []
    if hit is not None and hit > 0:
        what.append(f"vehicle {hit} hit")
    return {
        "f": row["f"],
        "crash": bool(row.get("crash", False)),
        "what": ", ".join(w for w in what if w) or None,
        "log_p0": row["log_p0"],
        "percentile": None
        if p0_sample is None
        else p0_percentile(row["log_p0"], p0_sample),
        "phase": row["phase"],
        "iteration": row.get("iteration"),
        "sample_id": row["sample_id"],
        "vehicles": vehicles,
        "params": params,
        "animation": animation,
    }
