"""The simulator seen as the estimation engine's batched black box.

:class:`SimulationObjective` maps ``X`` (n, D) and one seed per rollout to the
minimum time-to-collision ``f`` [s] plus per-rollout outcomes (event flags,
status, crash facts), which the engine passes on to the samples table without
using them.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from avrisk.agents.drivers.store import (
    DRIVER_NET_FILE,
    XI_PRIOR_FILE,
    default_drivers_dir,
)
from avrisk.assembly.builder import ScenarioSimulator
from avrisk.assembly.parts import base_distribution
from avrisk.assembly.traces import FailureRecorder
from avrisk.assembly.traffic import TrafficDrivers
from avrisk.fingerprint import sha256_file, sha256_json
from avrisk.rare import Product
from avrisk.scenario import ParamLayout, ScenarioSpec, spec_from_dict
from avrisk.sim.collision import Contact
from avrisk.sim.interfaces import weights_files
from avrisk.tensors.allocator import keep_freed_memory

__all__ = [
    "EVENT_COLUMNS",
    "FACT_COLUMNS",
    "FAILURE_COLUMN",
    "MECHANISMS",
    "ObjectiveFactory",
    "SimulationObjective",
]

#: Per-rollout event flags and step counts recorded besides ``f``.
EVENT_COLUMNS = ("crash", "offroad", "reversing", "steps")
#: Per-rollout status and crash facts recorded besides ``f``, with their
#: integer types (see :class:`avrisk.sim.rollout.RolloutResult`).
FACT_COLUMNS: dict[str, type[np.integer]] = {
    "status": np.int8,
    "collision_with": np.int16,
    "contact": np.int8,
}

#: Why a rollout failed, recorded when the ego policy says (its
#: ``failure_reasons``, shape (B,), for the batch last simulated).
FAILURE_COLUMN = "failure"


#: Largest change of a rollout's ``f`` [s] taken for rounding on a GPU: the
#: same rollouts on a GPU and on the CPU differ by up to about 1e-5 s on the
#: learned drivers of ``highway_default`` (``benchmarks/results/gpu_h100``),
#: and not at all on ``highway_idm``; an ego that acts otherwise moves a
#: near-hit by far more.
GPU_F_TOLERANCE = 1e-4

#: The per-rollout column by which ``p`` is decomposed, and its codes' names
#: (:class:`avrisk.sim.collision.Contact`; ``-1``: not recorded).
MECHANISMS: tuple[str, dict[int, str]] = (
    "contact",
    {
        int(Contact.NONE): "near miss (no contact)",
        int(Contact.REAR_END): "rear-end: the ego hits the vehicle ahead",
        int(Contact.FROM_BEHIND): "hit from behind",
        int(Contact.SIDE): "side contact",
        -1: "not recorded (older run)",
    },
)


class SimulationObjective:
    """``f(x, seeds)`` = minimum TTC of each rollout of a scenario [s].

    Parameters
    ----------
    spec : ScenarioSpec
        The scenario.
    device : str, default="cpu"
        Torch device of the simulator.
    allow_import : bool, default=False
        Whether components the spec names by import path may be imported
        (only for a spec given on the command line).
    dtype : torch.dtype, default=torch.float32
        Floating-point type of the simulation.
    traffic : TrafficDrivers, optional
        Other learned traffic drivers, the ego under test kept at the
        shipped weights (:mod:`avrisk.assembly.traffic`); default the shipped
        drivers.

    Attributes
    ----------
    needs_seeds : bool
        Always ``True``: a rollout's seed drives its stochastic parts.
    simulator : ScenarioSimulator
    failures : FailureRecorder or None
        Keeps the traces of the most likely dangerous rollouts, when set.
    """

    needs_seeds = True

    def __init__(
        self,
        spec: ScenarioSpec,
        *,
        device: str = "cpu",
        allow_import: bool = False,
        dtype: torch.dtype = torch.float32,
        traffic: TrafficDrivers | None = None,
    ) -> None:
        self.simulator = ScenarioSimulator(
            spec, device=device, dtype=dtype, allow_import=allow_import, traffic=traffic
        )
        self.failures: FailureRecorder | None = None

    def definition(self) -> dict[str, Any]:
        """What defines ``p`` for this objective, as hashes (a provenance stamp's).

        Returns
        -------
        dict
            ``scenario_sha256``: the resolved spec's canonical JSON (its
            component names and params included); ``weights_sha256``: each
            learned-weights file the simulation uses (the drivers', and the
            ego's own: ``weights_files``). With other traffic drivers
            (:class:`~avrisk.assembly.traffic.TrafficDrivers`) their files are
            ``traffic/driver_net.npz`` and ``traffic/xi_prior.npz`` (the
            shipped network stays, the ego's), and ``traffic_guard`` is their
            brake.
        """
        spec = self.simulator.spec
        drivers = default_drivers_dir()
        files = []
        if self.simulator.net is not None:
            files.append(DRIVER_NET_FILE)
        if spec.has_learned_drivers:
            files.append(XI_PRIOR_FILE)
        traffic = self.simulator.traffic
        if traffic is not None:  # the ego's network is the shipped one
            files = [f for f in files if f != XI_PRIOR_FILE]
        paths = {name: drivers / name for name in files}
        if traffic is not None:
            paths.update({f"traffic/{n}": p for n, p in traffic.files().items()})
        paths.update(weights_files(self.simulator.ego_policy))
        out = {
            "scenario_sha256": sha256_json(spec.model_dump(mode="json")),
            "weights_sha256": {name: sha256_file(path) for name, path in paths.items()},
        }
        if traffic is not None:
            out["traffic_guard"] = traffic.describe()["guard"]
        return out

    def base_distribution(self) -> Product:
        """``P0`` of the scenario, with the ``xi`` prior of its traffic drivers."""
        return base_distribution(self.simulator.spec, self.simulator.traffic)

    def computed_with(self) -> dict[str, Any]:
        """How this objective computes (device, precision, compiled or eager)."""
        sim = self.simulator
        return {
            "device": str(sim.device),
            "precision": str(sim.dtype).removeprefix("torch."),
            "compiled": sim.simulator.compile,
            "torch": torch.__version__,
        }

    def recording(self, failures: FailureRecorder) -> SimulationObjective:
        """The same objective (same simulator) recording into ``failures``."""
        other = copy.copy(self)
        other.failures = failures
        return other

    @property
    def device(self) -> str:
        """The simulator's torch device (``"cpu"``, ``"cuda:0"`` ...)."""
        return str(self.simulator.device)

    @property
    def replay_tolerance(self) -> float:
        """How far ``f`` of a rollout replayed at a resume may be from its record [s].

        0 on the CPU, whose rollouts do not depend on the batch they are
        simulated in; :data:`GPU_F_TOLERANCE` on a GPU, whose kernels may
        round otherwise for another batch size (and for a rollout recorded on
        the CPU).
        """
        return 0.0 if self.simulator.device.type == "cpu" else GPU_F_TOLERANCE

    @property
    def layout(self) -> ParamLayout:
        """Column layout of ``X``."""
        return self.simulator.layout

    def __call__(self, x: np.ndarray, seeds: np.ndarray) -> dict[str, np.ndarray]:
        """Simulate rows of ``x`` (shape (n, D)) with their seeds.

        Returns
        -------
        dict
            ``f`` (n,) float64 minimum TTC [s] (NaN where an actor failed);
            ``crash``, ``offroad``, ``reversing`` (n,) bool; ``steps`` (n,)
            int64; ``status`` (n,) int8 (0 ok, 1 an actor failed);
            ``collision_with`` (n,) int16 (vehicle hit, -1 none); ``contact``
            (n,) int8 (0 none, 1 rear-end, 2 hit from behind, 3 side); for
            an ego with ``failure_reasons`` (the external ego), ``failure``
            (n,) str: why a failed rollout failed, "" for the others.
        """
        record = self.failures is not None
        result = self.simulator.rollout(x, seeds, record_trace=record)
        if self.failures is not None:
            self.failures.offer(
                self.simulator, np.asarray(x), np.asarray(seeds), result
            )
        out = {"f": _numpy(result.f).astype(np.float64)}
        out.update({name: _numpy(getattr(result, name)) for name in EVENT_COLUMNS})
        out.update(
            {
                name: _numpy(getattr(result, name)).astype(kind)
                for name, kind in FACT_COLUMNS.items()
            }
        )
        reasons = getattr(self.simulator.ego_policy, "failure_reasons", None)
        if reasons is not None:  # an ego that says why it gave no action
            out[FAILURE_COLUMN] = np.where(out["status"] != 0, reasons, "")
        return out


@dataclass(frozen=True)
class ObjectiveFactory:
    """Builds a :class:`SimulationObjective` in a worker process, from data.

    What a worker (:mod:`avrisk.rare.parallel`) receives instead of the
    simulator: the resolved scenario as its JSON-ready dict, and how to build
    it. A worker computes with one CPU thread (one worker per core).

    Parameters
    ----------
    spec : dict
        ``ScenarioSpec.model_dump(mode="json")`` (what config.json records).
    device : str, default="cpu"
    allow_import : bool, default=False
        As for :class:`SimulationObjective` (the spec came from the command
        line, and the workers can import the same components).
    dtype : str, default="float32"
        Name of the torch floating-point type.
    traffic : TrafficDrivers, optional
        Other learned traffic drivers, as for :class:`SimulationObjective`.
    """

    spec: dict[str, Any]
    device: str = "cpu"
    allow_import: bool = False
    dtype: str = "float32"
    traffic: TrafficDrivers | None = None

    @classmethod
    def of(cls, objective: SimulationObjective, allow_import: bool) -> ObjectiveFactory:
        """The factory that builds ``objective`` again (its spec, device, dtype)."""
        sim = objective.simulator
        return cls(
            sim.spec.model_dump(mode="json"),
            objective.device,
            allow_import,
            str(sim.dtype).removeprefix("torch."),
            sim.traffic,
        )

    def __call__(self) -> SimulationObjective:
        """A new objective (one torch thread, freed memory kept for reuse)."""
        torch.set_num_threads(1)
        keep_freed_memory()
        return SimulationObjective(
            spec_from_dict(self.spec, source="the run's resolved scenario"),
            device=self.device,
            allow_import=self.allow_import,
            dtype=getattr(torch, self.dtype),
            traffic=self.traffic,
        )


def _numpy(t: torch.Tensor) -> np.ndarray:
    return t.detach().cpu().numpy()
