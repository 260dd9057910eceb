import functools
import gzip
import shutil

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

#: Not collected (``--doctest-modules`` would import them): importing one
#: registers an estimator or a backend, which ``tests/api/test_user_components.py``
#: and ``tests/api/test_backends.py`` do in a registry of their own.
collect_ignore = ["user_estimator.py", "user_backend.py"]


@pytest.fixture
def rng():
    """A fixed-seed generator (tests must pass for any seed; CI uses this one)."""
    return np.random.default_rng(20261122)


@pytest.fixture
def tiny_train_config():
    """A ``TrainConfig`` small enough for a test (seconds, not minutes)."""
    from avrisk.learning.train_config import ClosedLoopConfig, TrainConfig

    return TrainConfig(
        n_members=3,
        trunk_epochs=1,
        head_epochs=1,
        n_sim_rollouts=2,
        n_sim_val_rollouts=1,
        dagger_iters=1,
        dagger_rollouts=2,
        dagger_epochs=1,
        calibration_windows=4,
        calibration_steps=20,
        closed_loop=ClosedLoopConfig(
            iterations=2, batch_windows=4, window_steps=20, validate_every=1
        ),
    )


@pytest.fixture
def fake_ngsim(tmp_path, rng):
    """A folder holding the two NGSIM files training reads, with fake data."""
    folder = tmp_path / "ngsim"
    folder.mkdir()
    write_fake_ngsim(folder, rng)
    return folder


def write_fake_ngsim(folder, rng):
    """Two I-80 pairs (ft) and two lateral pairs (m) of smooth car following."""
    header = (
        "pair_id,period,follower_id,leader_id,lane_id,split,in_manifest,source_file,"
        "t,x_follower,v_follower,a_follower,x_leader,v_leader,a_leader,"
        "leader_length,spacing,dv"
    )
    lines = [header]
    for pid, split in ((1, "train"), (2, "test")):
        t = np.arange(120) * 0.1
        v_l = 30 + 3 * np.sin(t / 3)
        v_f = 30 + 3 * np.sin((t - 1) / 3)
        x_l = 100 + np.cumsum(v_l) * 0.1
        x_f = 40 + np.cumsum(v_f) * 0.1
        for k in range(len(t)):
            gap = x_l[k] - x_f[k] - 15
            meta = f"{pid},0400pm-0415pm,{10 + pid},{20 + pid},3,{split},1,f.csv"
            lines.append(
                f"{meta},{t[k]:.1f},{x_f[k]},{v_f[k]},0,{x_l[k]},{v_l[k]},0,15,"
                f"{gap},{v_f[k] - v_l[k]}"
            )
    with gzip.open(folder / "i80_cf_pairs.csv.gz", "wt") as f:
        f.write("\n".join(lines) + "\n")
    rows = []
    for follower in (31, 11):  # 11 is an I-80 train follower: stays in train
        for k in range(120):
            y = 50 + 9 * k * 0.1
            rows.append(
                {
                    "pair_id": f"{follower}-5", "time": k * 0.1, "duration": 12.0,
                    "vehicle_id": str(follower), "frame_id": 100.0 + k,
                    "local_x": 5.1 + 0.05 * rng.standard_normal(), "local_y": y,
                    "v_length": 4.5, "v_width": 1.8, "v_class": "2", "v_vel": 9.0,
                    "v_acc": 0.0, "lane_id": "2", "preceding": "5",
                    "space_headway": 20.0, "time_headway": 2.2,
                    "preceding_local_y": y + 20, "preceding_length": 4.6,
                    "preceding_width": 1.9, "preceding_class": "2",
                    "preceding_vel": 9.0, "preceding_acc": 0.0,
                }
            )  # fmt: skip
    pq.write_table(
        pa.Table.from_pylist(rows), folder / "i80_0400_0415_emd_cf_pairs.parquet"
    )


@pytest.fixture
def short_parts(monkeypatch):
    """Realism's part A windows cut to 3 s and part B's scenes to 6 s: seconds."""
    import avrisk.realism
    from avrisk.realism import RealismSettings

    monkeypatch.setattr(
        avrisk.realism,
        "RealismSettings",
        functools.partial(RealismSettings, window_s=3.0, horizon=6.0),
    )


@pytest.fixture
def drivers_copy(tmp_path):
    """A folder holding a copy of the shipped driver files."""
    from avrisk.agents.drivers.store import default_drivers_dir

    folder = tmp_path / "drivers"
    folder.mkdir()
    for name in ("driver_net.npz", "xi_prior.npz"):
        shutil.copy(default_drivers_dir() / name, folder / name)
    return folder
