"""The realism report: both parts run, then written to a folder.

:func:`run_realism` evaluates one driver model (a ``driver_net.npz`` and an
``xi_prior.npz``, :class:`DriverFiles`) on the held-out human data shipped
with the package: part A (:mod:`avrisk.realism.car_following`) and part B
(:mod:`avrisk.realism.lane_changes`). :func:`write_report` writes::

    realism.md          the tables: part A, issue 21's targets, collisions, lane changes
    realism.json        every figure, with the provenance (settings, hashes, versions)
    part_a_cdfs.png     part A's distributions
    lane_changes.png    part B's rates and manoeuvres
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any, Literal

import numpy as np
import pyarrow.compute as pc
import torch

from avrisk.agents.drivers.guard import BrakeGuard
from avrisk.agents.drivers.lane_change import LaneChangeParams
from avrisk.agents.drivers.store import (
    DRIVER_NET_FILE,
    XI_PRIOR_FILE,
    default_drivers_dir,
    load_driver_net,
    load_xi_prior,
)
from avrisk.fingerprint import sha256_file
from avrisk.learning.ngsim.us101_lane_changes import (
    HELD_OUT_FRACTION,
    SPLIT_SEED,
    LaneChangeTables,
    load_lane_change_tables,
    split_statistics,
)
from avrisk.pipeline.provenance import code_version
from avrisk.realism.car_following import (
    PartA,
    Progress,
    run_part_a,
    summarise_part_a,
)
from avrisk.realism.figures import draw_lane_changes, draw_part_a
from avrisk.realism.held_out import (
    HELD_OUT_TEST,
    data_files,
    held_out_period,
    held_out_windows,
    select_windows,
)
from avrisk.realism.lane_changes import (
    HORIZON,
    Scenes,
    TrafficLaneChanges,
    evaluate,
    summarise_lane_changes,
)
from avrisk.realism.metrics import DT
from avrisk.realism.periods import band_summaries, periods_table
from avrisk.realism.tables import (
    collision_table,
    lane_change_table,
    part_a_table,
    targets_table,
)
from avrisk.realism.targets import TargetResult, part_a_targets
from avrisk.scenario import xi_base_family
from avrisk.sim import Road

__all__ = [
    "DRIVERS_GUARD",
    "FILES",
    "DriverFiles",
    "RealismResult",
    "RealismSettings",
    "run_realism",
    "write_report",
]

#: What :func:`write_report` writes, by role.
FILES = {
    "tables": "realism.md",
    "figures": "realism.json",
    "part_a_figure": "part_a_cdfs.png",
    "part_b_figure": "lane_changes.png",
}

#: ``RealismSettings.guard``: the emergency brake the driver weights carry.
DRIVERS_GUARD = "drivers"


@dataclass(frozen=True)
class RealismSettings:
    """How much to simulate, and the seed.

    Attributes
    ----------
    seed : int, default=2024
        Part A's ``xi`` draws and noise; part B's scenes use ``seed + 1``.
    replicates : int, default=24
        Replays of every held-out window per model (24: 20.2 vehicle-hours,
        the benchmark's setting).
    windows : int or None, default=None
        Held-out windows evaluated, drawn at random with ``seed`` (None: all
        202; fewer for tests and quick looks).
    scenes : int, default=256
        Six-lane scenes per model in part B.
    window_s : float, default=15.0
        Length of a window [s].
    horizon : float, default=HORIZON
        Length of a part-B scene [s].
    guard : BrakeGuard, None or "drivers", default="drivers"
        The emergency brake of the learned drivers, in both parts
        (:mod:`avrisk.agents.drivers.guard`): ``"drivers"`` the one their
        weights carry (:data:`DRIVERS_GUARD`), None the network alone.
        :func:`run_realism` records the one it drove with.
    held_out : str, default="test"
        Part A's held-out windows (:func:`~avrisk.realism.held_out.
        held_out_windows`): ``"test"``, the test splits of every I-80
        period; or a period's name (e.g. ``"0500pm-0515pm"``), all of that
        period, for drivers trained on the other (``train-drivers
        --period``).
    """

    seed: int = 2024
    replicates: int = 24
    windows: int | None = None
    scenes: int = 256
    window_s: float = 15.0
    horizon: float = HORIZON
    guard: BrakeGuard | Literal["drivers"] | None = "drivers"
    held_out: str = HELD_OUT_TEST

    def __post_init__(self) -> None:
        known = self.guard is None or isinstance(self.guard, BrakeGuard)
        if not known and self.guard != DRIVERS_GUARD:
            raise ValueError(
                f"guard must be a BrakeGuard, None or {DRIVERS_GUARD!r}; "
                f"got {self.guard!r}"
            )


@dataclass(frozen=True)
class DriverFiles:
    """The two files of a driver model.

    Attributes
    ----------
    net, prior : Path
        ``driver_net.npz`` and ``xi_prior.npz``.
    shipped : bool
        Whether they are the package's (``avrisk/data/drivers/``).
    """

    net: Path
    prior: Path
    shipped: bool

    @classmethod
    def in_folder(cls, folder: Path | None) -> DriverFiles:
        """The model ``avrisk train-drivers`` wrote in ``folder``, or the shipped."""
        shipped = folder is None
        folder = default_drivers_dir() if folder is None else folder
        return cls(folder / DRIVER_NET_FILE, folder / XI_PRIOR_FILE, shipped)

    def hashes(self) -> dict[str, str]:
        """SHA-256 of each file, by file name."""
        return {p.name: sha256_file(p) for p in (self.net, self.prior)}


@dataclass(frozen=True)
class RealismResult:
    """Both parts of the report, with what they were run on.

    Attributes
    ----------
    settings : RealismSettings
    drivers : DriverFiles
    part_a : PartA
        The replays' samples (for the figure).
    summary_a : dict
        :func:`~avrisk.realism.car_following.summarise_part_a`.
    targets : dict of str to list of TargetResult
        :func:`~avrisk.realism.targets.part_a_targets`.
    part_b : dict of str to TrafficLaneChanges
        Per model of part B.
    summary_b : dict
        :func:`~avrisk.realism.lane_changes.summarise_lane_changes`.
    us101 : LaneChangeTables
        The shipped US-101 tables (the held-out humans' changes).
    windows_available : int
        Held-out windows there are (of which ``part_a`` drove a selection).
    seconds : dict of str to float
        Wall time of part A and part B [s].
    bands : dict of str to dict
        Part A per speed band
        (:func:`~avrisk.realism.periods.band_summaries`).
    """

    settings: RealismSettings
    drivers: DriverFiles
    part_a: PartA
    summary_a: dict[str, Any]
    targets: dict[str, list[TargetResult]]
    part_b: dict[str, TrafficLaneChanges]
    summary_b: dict[str, Any]
    us101: LaneChangeTables
    windows_available: int
    seconds: dict[str, float]
    bands: dict[str, dict[str, Any]]


def run_realism(
    drivers: DriverFiles,
    settings: RealismSettings,
    progress_a: Progress | None = None,
    progress_b: Progress | None = None,
) -> RealismResult:
    """Part A and part B for the driver model in ``drivers``.

    Parameters
    ----------
    drivers : DriverFiles
    settings : RealismSettings
    progress_a, progress_b : callable, optional
        ``progress(model, done, total)`` of each part.

    Returns
    -------
    RealismResult
    """
    net = load_driver_net(drivers.net)
    fam = xi_base_family(load_xi_prior(drivers.prior))
    s = settings
    if s.guard == DRIVERS_GUARD:
        s = replace(s, guard=net.guard)
    road = Road()
    t0 = time.perf_counter()
    everything = held_out_windows(round(s.window_s / DT), road, s.held_out)
    windows, labels = select_windows(everything, s.windows, s.seed)
    part_a = run_part_a(
        net,
        fam,
        windows,
        labels,
        seed=s.seed,
        replicates=s.replicates,
        road=road,
        progress=progress_a,
        guard=s.guard,
    )
    summary_a = summarise_part_a(part_a)
    t1 = time.perf_counter()
    tables = load_lane_change_tables()
    scenes = Scenes(s.scenes, s.seed + 1, s.horizon, fam)
    part_b = evaluate(
        net,
        scenes,
        LaneChangeParams(),
        tables.noise_speed,
        progress=progress_b,
        guard=s.guard,
    )
    summary_b = summarise_lane_changes(
        part_b, split_statistics(tables, "test"), split_statistics(tables, "train")
    )
    return RealismResult(
        settings=s,
        drivers=drivers,
        part_a=part_a,
        summary_a=summary_a,
        targets=part_a_targets(summary_a),
        part_b=part_b,
        summary_b=summary_b,
        us101=tables,
        windows_available=len(everything),
        seconds={"part_a": t1 - t0, "part_b": time.perf_counter() - t1},
        bands=band_summaries(part_a, road),
    )


def _provenance(result: RealismResult, command: str) -> dict[str, Any]:
    s, a, b = result.settings, result.summary_a, result.summary_b
    model_hours_a = next(iter(a["models"].values()))["vehicle_hours"]
    model_hours_b = next(iter(b["models"].values()))["driven_hours"]
    held_out_b = b["human_held_out"]
    return {
        "command": command,
        **code_version(),
        "torch": torch.__version__,
        "numpy": np.__version__,
        "torch_threads": torch.get_num_threads(),
        # the guard as the driver files write it (BrakeGuard.to_dict)
        "settings": asdict(s) | {"guard": s.guard and s.guard.to_dict()},
        "lane_change_layer": asdict(LaneChangeParams()),
        "drivers": {
            "shipped": result.drivers.shipped,
            "folder": str(result.drivers.net.parent),
            "sha256": result.drivers.hashes(),
        },
        "data_sha256": {p.name: sha256_file(p) for p in data_files().values()},
        "held_out": {
            "part_a": {
                "what": _held_out_words(s.held_out)
                + f", cut into non-overlapping {a['window_s']:g} s windows",
                "held_out": s.held_out,
                "windows_available": result.windows_available,
                "windows": a["windows"],
                # None: every window; else the held-out indices drawn.
                "indices": None
                if a["windows"] == result.windows_available
                else result.part_a.labels.tolist(),
            },
            "part_b": {
                "what": "US-101 vehicles held out at random before any fitting "
                "(avrisk.learning.ngsim.us101_lane_changes.us101_split)",
                "split_seed": SPLIT_SEED,
                "held_out_fraction": HELD_OUT_FRACTION,
                "vehicles": held_out_b["vehicles"],
                "changes": held_out_b["changes"],
            },
        },
        "vehicle_hours": {
            "part_a_human": a["human"]["vehicle_hours"],
            "part_a_per_model": model_hours_a,
            "part_b_human_held_out": held_out_b["hours"],
            "part_b_per_model": model_hours_b,
        },
        "seconds": result.seconds,
    }


def _held_out_words(held_out: str) -> str:
    period, test_only = held_out_period(held_out)
    if test_only:
        return (
            "NGSIM I-80 car-following episodes of the test split (pairs file's "
            "split column; lateral file by "
            "avrisk.learning.ngsim.loaders.lateral_pair_split)"
            + ("" if period is None else f" of the period {period} only")
        )
    return (
        f"every NGSIM I-80 car-following episode of the period {held_out} "
        "(both splits; the lateral file's too for 0400pm-0415pm, the only "
        "period it covers)"
    )


def markdown(result: RealismResult, command: str) -> str:
    """``realism.md``: the four tables and how they were made."""
    s = result.settings
    p = result.drivers
    drivers = "the shipped drivers" if p.shipped else f"the drivers in {p.net.parent}"
    hashes = ", ".join(f"{k} {v[:12]}" for k, v in p.hashes().items())
    seconds = sum(result.seconds.values())
    return "\n\n".join(
        [
            f"# Realism of the learned drivers against held-out human data\n\n"
            f"Drivers: {drivers} ({hashes}){_guard_words(s.guard)}. "
            f"Part A held out: {_held_out_words(s.held_out)}.",
            part_a_table(result.summary_a),
            targets_table(result.targets),
            periods_table([result]),
            collision_table(result.summary_a),
            lane_change_table(result.summary_b, s.scenes, s.horizon, s.seed + 1),
            f"![part A]({FILES['part_a_figure']})\n\n"
            f"![part B]({FILES['part_b_figure']})",
            f"_Command: `{command}`; {seconds:.0f} s, torch {torch.__version__}, "
            f"{torch.get_num_threads()} thread(s)._",
        ]
    )


def _guard_words(guard: BrakeGuard | None) -> str:
    if guard is None:
        return ""
    return (
        f", with an emergency brake (gap floor {guard.gap_floor:g} m, engaged "
        f"above {guard.engage_decel:g} m/s^2 of needed deceleration"
        + (", and whenever closing inside the floor)" if guard.hold_floor else ")")
    )


def write_report(result: RealismResult, out: Path, command: str) -> list[Path]:
    """Write :data:`FILES` into ``out`` (created); returns their paths.

    Parameters
    ----------
    result : RealismResult
    out : Path
        The folder.
    command : str
        The command line that made the report (recorded in both files).
    """
    out.mkdir(parents=True, exist_ok=True)
    paths = {role: out / name for role, name in FILES.items()}
    paths["tables"].write_text(markdown(result, command) + "\n")
    figures = {
        "provenance": _provenance(result, command),
        "part_a": result.summary_a,
        "part_a_targets": {
            name: [t.to_dict() for t in rows] for name, rows in result.targets.items()
        },
        "part_a_bands": result.bands,
        "part_b": result.summary_b,
    }
    paths["figures"].write_text(json.dumps(figures, indent=1, allow_nan=False) + "\n")
    draw_part_a(result.part_a, paths["part_a_figure"])
    events = result.us101.events.filter(pc.equal(result.us101.events["split"], "test"))
    draw_lane_changes(
        result.summary_b,
        result.part_b,
        events["duration_s"].to_numpy(),
        events["peak_lateral_speed"].to_numpy(),
        paths["part_b_figure"],
    )
    return list(paths.values())
