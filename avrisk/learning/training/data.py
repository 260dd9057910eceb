"""What the driver training reads: demonstrations and car-following windows.

:func:`~avrisk.learning.training.train.train_drivers` reads the NGSIM I-80
car-following pairs and lateral pairs of an NGSIM folder
(:mod:`avrisk.learning.ngsim.loaders`), split into train and test as the
source splits them
(:func:`~avrisk.learning.ngsim.loaders.lateral_pair_split` for the lateral
file):

* :func:`load_demonstrations` -- training demonstrations (the NGSIM train
  splits and IDM+MOBIL scenes) and validation ones (the test splits and
  IDM+MOBIL scenes of another seed), with the files' sha256;
* :func:`training_windows` -- car-following windows of the train splits, for
  the noise calibration and the replayed DAgger rounds.

Only the train splits are trained or calibrated on. ``TrainConfig.periods``
restricts both files to some recording periods (leave-one-period-out
validation, :mod:`avrisk.realism.held_out`): the lateral file, which covers
16:00-16:15 only (:data:`~avrisk.learning.ngsim.loaders.LATERAL_PERIOD`), is read
only when that period is among them.
"""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from avrisk.learning.imitation.demonstrations import Demonstrations
from avrisk.learning.imitation.ngsim_demonstrations import (
    i80_pair_demonstrations,
    lateral_pair_demonstrations,
)
from avrisk.learning.imitation.simulated_demonstrations import simulated_demonstrations
from avrisk.learning.ngsim.files import I80_LATERAL, I80_PAIRS, ngsim_file
from avrisk.learning.ngsim.lateral import LaneCentres
from avrisk.learning.ngsim.loaders import (
    LATERAL_PERIOD,
    lateral_pair_split,
    load_i80_lateral,
    load_i80_pairs,
    periods_of,
)
from avrisk.learning.ngsim.samples import CarFollowingPairs, LateralPairs
from avrisk.learning.replay import CarFollowingWindows, car_following_windows
from avrisk.learning.train_config import TrainConfig
from avrisk.sim import Road

__all__ = ["available_periods", "load_demonstrations", "training_windows"]


class _I80(NamedTuple):
    """The I-80 files of an NGSIM folder, loaded, and the lateral pairs' split."""

    files: tuple[Path, Path]
    pairs: CarFollowingPairs
    lateral: LateralPairs
    lateral_split: NDArray[np.str_]

    def part(self, split: str) -> tuple[CarFollowingPairs, LateralPairs]:
        """The car-following and lateral pairs of ``split`` (train or test)."""
        return (
            self.pairs.take(self.pairs.split == split),
            self.lateral.take(self.lateral_split == split),
        )


def _load_i80(
    data_dir: str | Path | None, periods: tuple[str, ...] | None = None
) -> _I80:
    """Both I-80 files, restricted to ``periods`` (None: all).

    The lateral pairs are split against all car-following pairs first, so
    that a period's split does not depend on which periods are kept.

    Raises
    ------
    ValueError
        For a period the pairs file does not hold.
    """
    files = (ngsim_file(I80_PAIRS, data_dir), ngsim_file(I80_LATERAL, data_dir))
    pairs = load_i80_pairs(files[0])
    lateral = load_i80_lateral(files[1])
    split = lateral_pair_split(lateral, pairs)
    if periods is None:
        return _I80(files, pairs, lateral, split)
    unknown = sorted(set(periods) - set(periods_of(pairs)))
    if unknown:
        raise ValueError(
            f"no I-80 period {unknown} in {files[0]}; it holds {periods_of(pairs)}"
        )
    keep = np.isin(pairs.period, periods)
    rows = np.full(len(lateral), LATERAL_PERIOD in periods)
    return _I80(files, pairs.take(keep), lateral.take(rows), split[rows])


def available_periods(data_dir: str | Path | None) -> tuple[str, ...]:
    """The recording periods of the I-80 pairs file in ``data_dir``, sorted."""
    return periods_of(load_i80_pairs(ngsim_file(I80_PAIRS, data_dir)))


def _lane_centres(lateral: LateralPairs) -> LaneCentres | None:
    """Centre lines fitted to ``lateral`` (None without lateral pairs)."""
    return LaneCentres.fit(lateral) if len(lateral) else None


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def load_demonstrations(
    data_dir: str | Path | None,
    seed: int,
    config: TrainConfig | None = None,
    road: Road | None = None,
) -> tuple[Demonstrations, Demonstrations, dict[str, Any]]:
    """Training and validation demonstrations from NGSIM and the simulator.

    Parameters
    ----------
    data_dir : str or Path or None
        NGSIM folder (:func:`avrisk.learning.ngsim.files.ngsim_dir`; None: the
        data shipped with the package), packed or original files.
    seed : int
        Seeds the simulated scenes (validation uses ``seed + 1``).
    config : TrainConfig, optional
        ``n_sim_rollouts``, ``n_sim_val_rollouts`` and ``sim_accel_weight``;
        default ``TrainConfig()``.
    road : Road, optional
        Default the scenario road ``Road()`` (6 lanes of 3.7 m).

    Returns
    -------
    train, val : Demonstrations
        NGSIM train splits + IDM+MOBIL; NGSIM test splits + IDM+MOBIL (other
        seed).
    meta : dict
        Files and their sha256, lane centres, per-source counts.
    """
    config = TrainConfig() if config is None else config
    road = Road() if road is None else road
    data = _load_i80(data_dir, config.periods)
    centres = _lane_centres(data.part("train")[1])
    offsets = iter(range(0, 10_000_000, 1_000_000))
    parts: dict[str, list[Demonstrations]] = {"train": [], "test": []}
    for name in ("train", "test"):
        pairs, lateral = data.part(name)
        parts[name].append(
            i80_pair_demonstrations(pairs, road, episode_offset=next(offsets))
        )
        offset = next(offsets)
        if centres is not None and len(lateral):
            parts[name].append(
                lateral_pair_demonstrations(
                    lateral, road, centres=centres, episode_offset=offset
                )
            )
    for name, n_rollouts, scene_seed in (
        ("train", config.n_sim_rollouts, seed),
        ("test", config.n_sim_val_rollouts, seed + 1),
    ):
        parts[name].append(
            simulated_demonstrations(
                n_rollouts,
                scene_seed,
                road=road,
                accel_weight=config.sim_accel_weight,
                episode_offset=next(offsets),
            )
        )
    train = Demonstrations.concat(parts["train"])
    val = Demonstrations.concat(parts["test"])
    meta = {
        "files": {f.name: _sha256(f) for f in data.files},
        "periods": periods_of(data.pairs),
        "lane_centres_m": None if centres is None else centres.to_dict(),
        "train": train.summary(),
        "val": val.summary(),
    }
    return train, val, meta


def training_windows(
    data_dir: str | Path | None,
    n_steps: int,
    periods: tuple[str, ...] | None = None,
) -> CarFollowingWindows:
    """Car-following windows of ``n_steps`` steps of the training splits.

    For the noise calibration, the replayed DAgger rounds and the closed
    loop; the lane centres are fitted to the training lateral pairs.
    ``periods`` keeps those recording periods only (None: all).
    """
    pairs, lateral = _load_i80(data_dir, periods).part("train")
    return car_following_windows(
        pairs, lateral, _lane_centres(lateral), n_steps, Road()
    )
