"""Two egos on the same draws: the paired black box of a release comparison.

:class:`PairedObjective` simulates every row of ``X`` twice, once with each
ego (``A`` and ``B``), from the same ``X`` and the same seed. ``X`` holds the
scenario's every random parameter (initial state, the learned drivers'
``xi``) and the seed the actors' noise, which is counter-based per actor
(:mod:`avrisk.tensors.noise`): the other vehicles draw the same numbers
whatever the ego does, so the two rollouts of a row differ by the ego alone
(common random numbers), and each world's traffic reacts to its own ego.

Its output is the engine's paired black box
(:class:`avrisk.rare.paired.MinOfPair`): ``f`` of shape (n, 2), each ego's
minimum TTC [s], and every per-rollout outcome of each ego as a column of its
own (``crash_a``, ``contact_b`` ...), with ``status`` non-zero where either
rollout failed.

:class:`PairedFactory` is what a worker process or a Ray task builds that
black box from (:mod:`avrisk.rare.parallel`): each ego's scenario as data.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from avrisk.assembly.objective import ObjectiveFactory, SimulationObjective
from avrisk.rare.paired import MinOfPair
from avrisk.rare.problem import STATUS

__all__ = ["PairedFactory", "PairedObjective"]

#: The suffix of each ego's columns, A's first.
SUFFIXES = ("_a", "_b")


class PairedObjective:
    """``(min TTC with ego A, min TTC with ego B)`` of each row of ``X`` [s].

    Parameters
    ----------
    a, b : SimulationObjective
        The scenario with each ego (the same scenario otherwise: the same
        layout of ``X``).

    Attributes
    ----------
    needs_seeds : bool
        Always ``True``: both rollouts of a row get its seed.
    """

    needs_seeds = True

    def __init__(self, a: SimulationObjective, b: SimulationObjective) -> None:
        if a.layout.columns != b.layout.columns:
            raise ValueError(
                "the two egos' scenarios lay out X differently: they must differ in "
                "the ego alone"
            )
        self.a, self.b = a, b

    @property
    def objectives(self) -> tuple[SimulationObjective, SimulationObjective]:
        """``(a, b)``."""
        return self.a, self.b

    @property
    def device(self) -> str:
        """Torch device both egos simulate on (``A``'s)."""
        return self.a.device

    @property
    def deterministic(self) -> bool:
        """Whether both egos vouch that a rollout depends only on ``X`` and seed."""
        return all(o.simulator.deterministic for o in self.objectives)

    @property
    def replay_tolerance(self) -> float:
        """The larger of the two objectives' replay tolerances [s]."""
        return max(o.replay_tolerance for o in self.objectives)

    def definition(self) -> dict[str, Any]:
        """What defines both probabilities: each ego's scenario and weights hashes."""
        return {"a": self.a.definition(), "b": self.b.definition()}

    def computed_with(self) -> dict[str, Any]:
        """How the rollouts are computed (both egos' simulators alike)."""
        return self.a.computed_with()

    def __call__(self, x: np.ndarray, seeds: np.ndarray) -> dict[str, np.ndarray]:
        """Simulate rows of ``x`` (shape (n, D)) with both egos and the same seeds.

        Returns
        -------
        dict
            ``f`` (n, 2) float64: each ego's minimum TTC [s] (NaN where its
            rollout failed); ``status`` (n,) int8: non-zero where either
            failed; each ego's outcome columns (:meth:`SimulationObjective.__call__`)
            with the suffix ``_a`` or ``_b``.
        """
        outs = [o(x, seeds) for o in self.objectives]
        merged: dict[str, np.ndarray] = {
            "f": np.stack([out["f"] for out in outs], axis=1),
            STATUS: np.maximum(*(out[STATUS] for out in outs)).astype(np.int8),
        }
        for out, suffix in zip(outs, SUFFIXES, strict=True):
            merged.update(
                (f"{name}{suffix}", column)
                for name, column in out.items()
                if name != "f"
            )
        return merged


@dataclass(frozen=True)
class PairedFactory:
    """Builds the paired black box ``MinOfPair(PairedObjective(A, B))`` in a worker.

    What a worker receives instead of the two simulators: each ego's
    :class:`~avrisk.assembly.objective.ObjectiveFactory` (its resolved
    scenario as data). The box it builds evaluates a chunk as the run's own
    does in this process (:class:`~avrisk.rare.paired.MinOfPair`): ``f`` the
    lower minimum TTC [s], ``f_a``, ``f_b`` and each ego's outcome columns.

    Parameters
    ----------
    a, b : ObjectiveFactory
        Ego ``A``'s and ego ``B``'s.
    """

    a: ObjectiveFactory
    b: ObjectiveFactory

    @classmethod
    def of(cls, objective: PairedObjective, allow_import: bool) -> PairedFactory:
        """The factory that builds ``objective``'s box again (specs, device, dtype)."""
        return cls(
            ObjectiveFactory.of(objective.a, allow_import),
            ObjectiveFactory.of(objective.b, allow_import),
        )

    def __call__(self) -> MinOfPair:
        """A new box: both egos' objectives, each on one torch thread."""
        return MinOfPair(PairedObjective(self.a(), self.b()))
