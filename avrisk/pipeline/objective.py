"""The simulator seen as the estimation engine's batched black box.

:class:`SimulationObjective` maps ``X`` (n, D) and one seed per rollout to the
minimum time-to-collision ``f`` [s] plus the event flags, which the engine
passes on to the samples table without using them.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch

from avrisk.scenario import ParamLayout, ScenarioSpec
from avrisk.scenario.builder import ScenarioSimulator

#: Per-rollout outputs recorded besides ``f``.
EVENT_COLUMNS = ("crash", "offroad", "reversing", "steps")


class SimulationObjective:
    """``f(x, seeds)`` = minimum TTC of each rollout of a scenario [s].

    Parameters
    ----------
    spec : ScenarioSpec
        The scenario.
    device : str, default="cpu"
        Torch device of the simulator.

    Attributes
    ----------
    needs_seeds : bool
        Always ``True``: a rollout's seed drives its stochastic parts.
    simulator : ScenarioSimulator
    """

    needs_seeds = True

    def __init__(self, spec: ScenarioSpec, *, device: str = "cpu") -> None:
        self.simulator = ScenarioSimulator(spec, device=device)

    @property
    def layout(self) -> ParamLayout:
        """Column layout of ``X``."""
        return self.simulator.layout

    def __call__(self, x: np.ndarray, seeds: np.ndarray) -> dict[str, np.ndarray]:
        """Simulate rows of ``x`` (shape (n, D)) with their seeds.

        Returns
        -------
        dict
            ``f`` (n,) float64 minimum TTC [s]; ``crash``, ``offroad``,
            ``reversing`` (n,) bool; ``steps`` (n,) int64.
        """
        result = self.simulator.rollout(x, seeds)
        out = {"f": _numpy(result.f).astype(np.float64)}
        out.update({name: _numpy(getattr(result, name)) for name in EVENT_COLUMNS})
        return out

    def animate(self, rows: Sequence[dict[str, Any]], path: Path) -> Path:
        """Re-simulate samples-table rows with traces and write a top-down GIF."""
        from avrisk.report.animate import animate_rollouts, traces_from_rollout

        x = np.array([[row[c] for c in self.layout.columns] for row in rows])
        seeds = np.array([row["seed"] for row in rows], dtype=np.int64)
        result = self.simulator.rollout(x, seeds, record_trace=True)
        labels = [f"min TTC {row['f']:.2f} s" for row in rows]
        traces = traces_from_rollout(self.simulator, x, result, labels=labels)
        spec = self.simulator.spec
        path.parent.mkdir(parents=True, exist_ok=True)
        animate_rollouts(traces, spec.road, spec.simulation.dt, path)
        return path


def _numpy(t: torch.Tensor) -> np.ndarray:
    return t.detach().cpu().numpy()
