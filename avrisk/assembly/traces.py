"""Recorded rollouts: traces of a batch as plain arrays, and the failures kept.

* :class:`RolloutTrace` -- one rollout's trajectories as NumPy arrays;
  :func:`traces_from_rollout` makes them from a batch simulated with
  ``record_trace=True``.
* :class:`FailureRecorder` -- while a run goes on, keeps the traces of the
  ``k`` most likely dangerous rollouts seen (``f <= gamma``, ranked as the
  report ranks them: :meth:`avrisk.assembly.typicality.Typicality.rank`) in
  ``failures.parquet`` of the run directory, so that a report
  shows them without simulating again: it needs neither the ego (an external
  AV need not be running, nor repeatable) nor any code a spec names.
  :func:`read_failure_traces` reads the file back, checked.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import torch
from numpy.typing import NDArray

from avrisk.assembly.builder import ScenarioSimulator

__all__ = [
    "FAILURES_FILE",
    "FailureRecorder",
    "RolloutTrace",
    "read_failure_traces",
    "resimulate",
    "traces_from_rollout",
    "ttc_series",
]

FloatArray = NDArray[np.float64]

#: The file of recorded failure traces in a run directory.
FAILURES_FILE = "failures.parquet"
#: Largest failures file read back [bytes] (a run directory is untrusted input).
MAX_FAILURES_BYTES = 64 << 20
_FRAME_FIELDS = ("x", "y", "heading", "speed")


@dataclass(frozen=True)
class RolloutTrace:
    """One recorded rollout, as plain arrays.

    Attributes
    ----------
    x, y : ndarray of shape (T+1, A)
        Centre position along the road and from the right road edge [m].
    heading : ndarray of shape (T+1, A)
        Heading, ccw from the road direction [rad].
    speed : ndarray of shape (T+1, A)
        Speed [m/s].
    length, width : ndarray of shape (A,)
        Vehicle size [m]; vehicle 0 is the ego.
    ttc_so_far : ndarray of shape (T+1,)
        Minimum time-to-collision up to and including each step [s] (inf when
        nothing has approached the ego yet).
    n_frames : int
        Steps actually simulated plus one (the rollout may stop at a crash).
    crashed : bool
        Whether the rollout ended in a crash.
    label : str
        Shown in the panel title, e.g. ``"row 12"``.
    hit : int
        Vehicle the ego crashed into (index into the vehicles; -1: none).
    """

    x: FloatArray
    y: FloatArray
    heading: FloatArray
    speed: FloatArray
    length: FloatArray
    width: FloatArray
    ttc_so_far: FloatArray
    n_frames: int
    crashed: bool
    label: str = ""
    hit: int = -1

    @property
    def min_ttc(self) -> float:
        """Minimum time-to-collision of the whole rollout [s]."""
        return float(self.ttc_so_far[self.n_frames - 1])


def ttc_series(ttc: FloatArray, alive: np.ndarray) -> FloatArray:
    """Minimum time-to-collision so far at every recorded step [s].

    Parameters
    ----------
    ttc : ndarray of shape (B, T+1)
        Instantaneous TTC of each frame (a recorded trace's ``ttc``) [s].
    alive : ndarray of bool, shape (B, T+1)
        Whether each frame was simulated.

    Returns
    -------
    ndarray of shape (B, T+1)
        Running minimum over steps ``0..k``; constant after a rollout ends;
        ``inf`` while nothing approaches.
    """
    return np.minimum.accumulate(np.where(alive, ttc, np.inf), axis=1)


def traces_from_rollout(
    sim: ScenarioSimulator,
    x: FloatArray,
    result: Any,
    *,
    labels: Sequence[str] | None = None,
    rows: Sequence[int] | None = None,
) -> list[RolloutTrace]:
    """Turn a recorded batch rollout into per-rollout traces.

    Parameters
    ----------
    sim : avrisk.assembly.ScenarioSimulator
        The simulator that produced ``result`` (for vehicle sizes).
    x : ndarray of shape (B, D)
        The flat scenario samples that were simulated.
    result : avrisk.sim.rollout.RolloutResult
        With ``trace`` recorded (``record_trace=True``).
    labels : sequence of str or None
        One label per rollout returned.
    rows : sequence of int or None
        The rollouts of the batch to return (default: all).

    Returns
    -------
    list of RolloutTrace
        One per rollout of ``rows`` (length ``B`` by default).
    """
    trace = result.trace
    if trace is None:
        raise ValueError("the rollout was run without record_trace=True")

    chosen = list(range(len(result.f))) if rows is None else list(rows)
    pick = torch.as_tensor(chosen, dtype=torch.long, device=result.f.device)

    def np_(t: Any) -> np.ndarray:  # only the chosen rollouts leave the device
        return t.index_select(0, pick).detach().cpu().numpy()

    xs, ys, hs, vs = (
        np_(getattr(trace, k)).astype(np.float64)
        for k in ("x", "y", "heading", "speed")
    )
    alive = np_(trace.alive).astype(bool)
    ttc = ttc_series(np_(trace.ttc).astype(np.float64), alive)
    spec = sim.spec
    length = np.array([v.length for v in spec.vehicles], dtype=np.float64)
    width = np.array([v.width for v in spec.vehicles], dtype=np.float64)
    crash = np_(result.crash).astype(bool)
    hit = np_(result.collision_with).astype(np.int64)
    out = []
    for n in range(len(chosen)):
        n_frames = int(alive[n].sum()) if alive[n].any() else 1
        out.append(
            RolloutTrace(
                x=xs[n],
                y=ys[n],
                heading=hs[n],
                speed=vs[n],
                length=length,
                width=width,
                ttc_so_far=ttc[n],
                n_frames=n_frames,
                crashed=bool(crash[n]),
                label=labels[n] if labels is not None else "",
                hit=int(hit[n]),
            )
        )
    return out


def resimulate(
    sim: ScenarioSimulator,
    x: FloatArray,
    seeds: np.ndarray,
    labels: Sequence[str] | None = None,
) -> tuple[Any, list[RolloutTrace]]:
    """Simulate given rollouts again, with their traces.

    Parameters
    ----------
    sim : ScenarioSimulator
    x : ndarray of shape (B, D)
        Rows of ``X`` in ``sim.layout``.
    seeds : ndarray of int64, shape (B,)
    labels : sequence of str, optional
        One per rollout, for animations.

    Returns
    -------
    result : avrisk.sim.rollout.RolloutResult
    traces : list of RolloutTrace
    """
    result = sim.rollout(x, seeds, record_trace=True)
    return result, traces_from_rollout(sim, x, result, labels=labels)


class FailureRecorder:
    """Keeps the traces of the ``k`` most likely dangerous rollouts of a run.

    A rollout is dangerous when ``f <= gamma``; "most likely" is the highest
    key of ``rank`` (the report's ranking of failures). Rollouts are identified by
    their seed, which the engine derives from the run seed, the stage and the
    sample id. The file is rewritten (atomically) whenever the kept set
    changes, and read back when a run resumes, so an interruption loses
    nothing that a replayed chunk would not give again.

    Parameters
    ----------
    path : Path
        The failures file (``DIR/failures.parquet``).
    gamma : float
        Threshold of a dangerous rollout [s].
    k : int
        How many to keep.
    rank : callable
        ``rank(x)``: keys of rows ``x`` (n, D), shape (n, m), compared
        lexicographically, the most likely highest.
    """

    def __init__(
        self,
        path: Path,
        gamma: float,
        k: int,
        rank: Callable[[np.ndarray], np.ndarray],
    ) -> None:
        self.path = Path(path)
        self.gamma = gamma
        self.k = k
        self.rank = rank
        self.kept: dict[int, tuple[tuple[float, ...], RolloutTrace]] = {}
        if self.path.is_file():
            self.kept = {
                seed: (score, trace)
                for seed, (score, trace) in read_failure_traces(self.path).items()
            }

    def offer(
        self,
        sim: ScenarioSimulator,
        x: np.ndarray,
        seeds: np.ndarray,
        result: Any,
    ) -> None:
        """Consider a simulated batch (recorded with ``record_trace=True``)."""
        f = result.f.detach().cpu().numpy().astype(np.float64)
        hits = np.flatnonzero(f <= self.gamma)
        if hits.size == 0 or self.k == 0:
            return
        scores = [tuple(map(float, key)) for key in self.rank(x[hits])]
        floor = self._floor()
        better = [j for j, score in enumerate(scores) if floor is None or score > floor]
        if not better:
            return
        rows = hits[better].tolist()
        traces = traces_from_rollout(sim, x, result, rows=rows)
        for i, j, trace in zip(rows, better, traces, strict=True):
            self.kept[int(seeds[i])] = (scores[j], trace)
        ranked = sorted(self.kept.items(), key=lambda kv: kv[1][0], reverse=True)
        self.kept = dict(ranked[: self.k])
        self._write()

    def _floor(self) -> tuple[float, ...] | None:
        """The lowest key kept once ``k`` are (None: any failure is kept)."""
        if len(self.kept) < self.k:
            return None
        return min(score for score, _ in self.kept.values())

    def _write(self) -> None:
        seeds = list(self.kept)
        traces = [self.kept[s][1] for s in seeds]
        columns: dict[str, Any] = {
            "seed": pa.array(seeds, pa.int64()),
            "rank": pa.array(
                [list(self.kept[s][0]) for s in seeds], pa.list_(pa.float64())
            ),
            "n_frames": pa.array([t.n_frames for t in traces], pa.int32()),
            "crashed": pa.array([t.crashed for t in traces], pa.bool_()),
            "n_vehicles": pa.array([t.x.shape[1] for t in traces], pa.int32()),
            "length": [t.length.tolist() for t in traces],
            "width": [t.width.tolist() for t in traces],
            "ttc_so_far": [t.ttc_so_far.tolist() for t in traces],
        }
        for name in _FRAME_FIELDS:
            columns[name] = [getattr(t, name).ravel().tolist() for t in traces]
        tmp = self.path.with_name(f".{self.path.name}.tmp-{os.getpid()}")
        try:
            pq.write_table(pa.table(columns), tmp)
            os.replace(tmp, self.path)
        except BaseException:
            tmp.unlink(missing_ok=True)
            raise


class FailureFileError(ValueError):
    """A failures file that is not what avrisk writes (refused, not trusted)."""


def read_failure_traces(
    path: Path,
) -> dict[int, tuple[tuple[float, ...], RolloutTrace]]:
    """The recorded failures of a run: ``{seed: (rank key, trace)}``.

    A file written before failures were ranked by their percentiles holds
    ``log_p0`` instead of a key: its traces read with the empty key, the
    lowest (a resumed run replaces them as it finds failures).

    Raises
    ------
    FailureFileError
        If the file is too large, lacks a column, or its arrays do not have
        the shapes its own counts give (it is never trusted blindly).
    """
    if path.stat().st_size > MAX_FAILURES_BYTES:
        raise FailureFileError(f"{path} is larger than {MAX_FAILURES_BYTES} bytes")
    try:
        rows = pq.read_table(path).to_pylist()
    except (pa.ArrowException, OSError) as err:
        raise FailureFileError(
            f"{path} is not a readable failures file: {err}"
        ) from None
    out = {}
    for row in rows:
        try:
            a = int(row["n_vehicles"])
            ttc = np.asarray(row["ttc_so_far"], dtype=np.float64)
            frames = {
                name: np.asarray(row[name], dtype=np.float64).reshape(len(ttc), a)
                for name in _FRAME_FIELDS
            }
            trace = RolloutTrace(
                **frames,
                length=np.asarray(row["length"], dtype=np.float64).reshape(a),
                width=np.asarray(row["width"], dtype=np.float64).reshape(a),
                ttc_so_far=ttc,
                n_frames=int(row["n_frames"]),
                crashed=bool(row["crashed"]),
            )
            if not 1 <= trace.n_frames <= len(ttc):
                raise ValueError("n_frames out of range")
            key = tuple(float(v) for v in row["rank"]) if "rank" in row else ()
            out[int(row["seed"])] = (key, trace)
        except (KeyError, TypeError, ValueError) as err:
            raise FailureFileError(f"{path}: a malformed row ({err})") from None
    return out
