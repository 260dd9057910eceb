"""What the vehicles sense of a state: geometry, lidar, camera, the observation.

:class:`Sensors` turns a batch's state into what the actors observe
(:class:`~avrisk.sim.observation.Observation`): the headings' cosines and
sines, which vehicles overlap, road departure and reversing, the lane
features (:class:`Geometry`), every vehicle's lidar scan and the ego's camera
image, each computed only when an actor reads it. Eager on a CPU, ray casting
works through the batch in cache-sized slices (:func:`in_cache_slices`); the
values are the same in any slicing.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, NamedTuple

import torch
from torch import Tensor

from avrisk.sim.camera import Camera, CameraFrame, reads_camera
from avrisk.sim.collision import offroad, pairwise_overlap, reversing
from avrisk.sim.config import SimConfig
from avrisk.sim.interfaces import Actor, reads_lidar
from avrisk.sim.lidar import LidarScan, beam_directions, lidar_scan
from avrisk.sim.observation import LaneFeatures, Observation, lane_features
from avrisk.sim.road import Road
from avrisk.sim.state import VehicleState
from avrisk.tensors.slices import in_slices

__all__ = [
    "Geometry",
    "Sensors",
    "any_reads_camera",
    "any_reads_lidar",
    "in_cache_slices",
]

# Eager ray casting on a CPU works through the batch in slices of about this
# many ray-box tests (avrisk.tensors.slices): the temporaries (128k floats,
# 512 KiB) then stay in the CPU's L2 cache and below glibc's mmap threshold,
# instead of being mapped, page-faulted and zeroed afresh by every operation
# (BENCHMARKS.md, "Simulator throughput"). Results are the same: every
# operation is elementwise along the batch.
_EAGER_CHUNK_TESTS = 1 << 17


def in_cache_slices(
    fn: Callable[..., Any], tests_per_rollout: Callable[[int], int]
) -> Callable[..., Any]:
    """``fn(state, cos, sin)`` evaluated on cache-sized batch slices, concatenated.

    ``tests_per_rollout(A)`` is the number of ray-box tests ``fn`` makes per
    rollout of ``A`` vehicles; the slices hold about ``2**17`` tests.
    """

    def chunked(state: VehicleState, cos: Tensor, sin: Tensor) -> Any:
        per_rollout = tests_per_rollout(state.n_vehicles)
        args = (state, cos, sin)
        return in_slices(fn, args, per_rollout, _EAGER_CHUNK_TESTS, cos.device)

    return chunked


def any_reads_lidar(actors: Sequence[Actor]) -> bool:
    """Whether some actor reads the lidar (else it is not scanned; same results)."""
    return any(reads_lidar(actor) for actor in actors)


def any_reads_camera(actors: Sequence[Actor]) -> bool:
    """Whether some actor reads the ego camera (else it is not rendered)."""
    return any(reads_camera(actor) for actor in actors)


class Geometry(NamedTuple):
    """What one state implies, short of ray casting: fields of shape (B, A)."""

    cos: Tensor  # [B, A]
    sin: Tensor  # [B, A]
    overlap: Tensor  # [B, A, A] bool
    offroad: Tensor  # [B, A] bool
    reversing: Tensor  # [B, A] bool
    lane: LaneFeatures


class Sensors:
    """A simulator's sensing: from a state to what its actors observe.

    Parameters
    ----------
    road : Road
    config : SimConfig
        Its lidar (``n_lidar_beams``, ``lidar_range``) and ``dt``.
    camera : Camera or None
        The ego's camera, rendered only when an actor reads it.
    dtype : torch.dtype
    device : torch.device
    """

    def __init__(
        self,
        road: Road,
        config: SimConfig,
        camera: Camera | None,
        dtype: torch.dtype,
        device: torch.device,
    ) -> None:
        self.road = road
        self.config = config
        self.camera = camera
        self._beams = (
            beam_directions(config.n_lidar_beams, dtype=dtype, device=device)
            if config.n_lidar_beams > 0
            else None
        )

    def geometry(self, state: VehicleState) -> Geometry:
        """Headings' cosines and sines, overlaps, road departure, reversing, lanes."""
        cos, sin = state.cos_sin
        return Geometry(
            cos=cos,
            sin=sin,
            overlap=pairwise_overlap(state, cos, sin),
            offroad=offroad(state, cos, sin, self.road),
            reversing=reversing(state, cos),
            lane=lane_features(state, self.road),
        )

    def scan(self, state: VehicleState, cos: Tensor, sin: Tensor) -> LidarScan:
        """The lidar; eager on a CPU, in cache-sized slices of the batch.

        Eager, every other vehicle is scanned at once (temporaries of
        ``A (A - 1) R`` elements per rollout) while the whole batch's fit in
        one slice, and beyond that one vehicle at a time (``A R`` per rollout,
        ``A - 1`` times as many operations), which is the faster of the two at
        large batches (BENCHMARKS.md, "Simulator throughput"). Compiled,
        always one at a time (:func:`avrisk.sim.lidar.nearest_box`). The same
        values every way.
        """
        beams = self._beams
        assert beams is not None
        a, n_beams = state.n_vehicles, self.config.n_lidar_beams
        at_once = a * (a - 1) * n_beams
        large = state.x.shape[0] * at_once > _EAGER_CHUNK_TESTS
        one_at_a_time = True if large and cos.device.type == "cpu" else None
        per_rollout = a * n_beams if one_at_a_time else at_once

        def scan(state: VehicleState, cos: Tensor, sin: Tensor) -> LidarScan:
            return lidar_scan(
                state,
                cos,
                sin,
                self.road,
                *beams,
                self.config.lidar_range,
                one_at_a_time,
            )

        args = (state, cos, sin)
        return in_slices(scan, args, per_rollout, _EAGER_CHUNK_TESTS, cos.device)

    def lidar(self, state: VehicleState, geo: Geometry) -> LidarScan | None:
        """Every vehicle's lidar scan, or None for a configuration without lidar."""
        return None if self._beams is None else self.scan(state, geo.cos, geo.sin)

    def camera_frame(
        self, state: VehicleState, actors: Sequence[Actor]
    ) -> CameraFrame | None:
        """The ego camera's image when an actor reads it, else None."""
        if self.camera is None or not any_reads_camera(actors):
            return None
        return self.camera(state)

    def observation(
        self,
        state: VehicleState,
        geo: Geometry,
        lidar: LidarScan | None,
        seeds: Tensor,
        step: int | Tensor,
        camera: CameraFrame | None = None,
    ) -> Observation:
        """What the actors receive at ``step``, from the state and its sensing."""
        return Observation(
            state=state,
            lidar=lidar,
            lane=geo.lane,
            collided=geo.overlap.any(dim=-1),
            offroad=geo.offroad,
            reversing=geo.reversing,
            seeds=seeds,
            step=step,
            dt=self.config.dt,
            camera=camera,
        )
