"""A dangerous rollout as a failure card of the report shows it.

Each parameter with its unit; with the scenario at hand, the vehicles' start
at absolute positions (``x`` [m] along the road, ``y`` [m] from its right
edge, as the simulator places them: :func:`avrisk.assembly.initial_state`) and
how typical its start and its drivers are under P0, as two percentiles
(:mod:`avrisk.assembly.typicality`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import torch

from avrisk.assembly import MECHANISMS, Typicality, initial_state
from avrisk.scenario import ScenarioSpec
from avrisk.scenario.params import XI_PREFIX, ParamLayout, ScenarioParams


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
    typical: Typicality | None,
    *,
    names: Sequence[str],
    units: Mapping[str, str],
    step: str,
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
    typical : Typicality or None
        Its scenario's, to read the start and the drivers as percentiles.
    names : sequence of str
        The rollout's parameters, by column name.
    units : mapping of str to str
        Unit of each column, as the run directory records them.
    step : str
        The step of the run that drew it, as its diagnostics name it
        (:meth:`~avrisk.rare.estimator.Estimator.stage_label`).
    animation : str or None
        Path of its animation, relative to the report.

    Returns
    -------
    dict
        ``f`` [s], ``crash``, ``what`` (mechanism and vehicle hit, or None),
        ``log_p0``, ``situation`` and ``drivers`` (percentiles in [0, 100],
        or None), ``step``, ``sample_id``, ``vehicles``
        (:func:`vehicle_starts`, or empty), ``params`` (text of the
        parameters not in ``vehicles``) and ``animation``.
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
    situation = drivers = None
    if typical is not None:
        share = typical.percentiles(
            np.array([[row[c] for c in typical.columns]]), np.array([row["log_p0"]])
        )
        situation = float(share.situation[0])
        drivers = None if share.drivers is None else float(share.drivers[0])
    return {
        "f": row["f"],
        "crash": bool(row.get("crash", False)),
        "what": ", ".join(w for w in what if w) or None,
        "log_p0": row["log_p0"],
        "situation": situation,
        "drivers": drivers,
        "step": step,
        "sample_id": row["sample_id"],
        "vehicles": vehicles,
        "params": params,
        "animation": animation,
    }
