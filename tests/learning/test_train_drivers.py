import dataclasses
import json

import pytest
import torch

from avrisk.agents.drivers.guard import BrakeGuard
from avrisk.agents.drivers.store import XiPrior, load_driver_net
from avrisk.agents.drivers.xi import XI_DIM
from avrisk.learning.training.data import training_windows
from avrisk.learning.training.selection import CandidateScore, choose
from avrisk.learning.training.train import CANDIDATES_DIR, train_drivers


@pytest.mark.slow
def test_train_drivers_writes_loadable_weights_a_prior_and_a_report(
    tmp_path, fake_ngsim, tiny_train_config
):
    report = train_drivers(
        3, tmp_path / "out", data_dir=fake_ngsim, config=tiny_train_config
    )
    net = load_driver_net(tmp_path / "out" / "driver_net.npz")
    assert net.guard == tiny_train_config.guard == BrakeGuard(2.0, 2.0, hold_floor=True)
    prior = XiPrior.load(tmp_path / "out" / "xi_prior.npz")
    assert prior.members.shape == (3, XI_DIM) and 0 < prior.sparsity <= 1
    assert net.default_xi.shape == (XI_DIM,)
    saved = json.loads((tmp_path / "out" / "training_report.json").read_text())
    assert saved["seed"] == 3 and set(report.files) == {
        "driver_net.npz",
        "xi_prior.npz",
    }
    assert len(saved["trunk_history"]) == 1 and len(saved["dagger_history"]) == 1
    assert [row["iteration"] for row in saved["closed_loop_history"]] == [0, 1, 2]
    kernels = saved["environment"]["cpu_kernels"]
    assert kernels["torch"] == torch.backends.cpu.get_cpu_capability()
    assert kernels["blas"]  # numpy's OpenBLAS at least


@pytest.mark.slow
def test_candidates_keep_the_training_with_the_fewest_validation_crashes(
    tmp_path, fake_ngsim, tiny_train_config
):
    out = tmp_path / "out"
    report = train_drivers(
        3, out, data_dir=fake_ngsim, config=tiny_train_config, candidates=2
    )
    scores = [CandidateScore(**row) for row in report.selection["candidates"]]
    assert [s.seed for s in scores] == [3, 4]
    assert report.selection["chosen_seed"] == choose(scores).seed == report.seed
    n_windows = len(training_windows(fake_ngsim, 20))
    assert all(s.replays == 8 * max(1, round(0.2 * n_windows)) for s in scores)
    chosen = out / CANDIDATES_DIR / f"seed-{report.seed}"
    for name in ("driver_net.npz", "xi_prior.npz"):
        assert (out / name).read_bytes() == (chosen / name).read_bytes()
    saved = json.loads((out / "training_report.json").read_text())
    assert saved["selection"] == report.selection
    # A candidate is the single training of its seed.
    alone = train_drivers(
        4, tmp_path / "alone", data_dir=fake_ngsim, config=tiny_train_config
    )
    assert alone.selection is None
    assert (tmp_path / "alone" / "driver_net.npz").read_bytes() == (
        out / CANDIDATES_DIR / "seed-4" / "driver_net.npz"
    ).read_bytes()
    with pytest.raises(ValueError, match="candidates"):
        train_drivers(3, tmp_path / "x", data_dir=fake_ngsim, candidates=0)
    # In two worker processes: the same candidates, scores and choice.
    par = train_drivers(
        3,
        tmp_path / "par",
        data_dir=fake_ngsim,
        config=tiny_train_config,
        candidates=2,
        workers=2,
    )
    assert par.selection == report.selection
    for seed in (3, 4):
        for name in ("driver_net.npz", "xi_prior.npz"):
            here = out / CANDIDATES_DIR / f"seed-{seed}" / name
            there = tmp_path / "par" / CANDIDATES_DIR / f"seed-{seed}" / name
            assert here.read_bytes() == there.read_bytes()


@pytest.mark.slow
def test_train_drivers_with_an_idm_head_fits_its_parameters_and_writes_them(
    tmp_path, fake_ngsim, tiny_train_config
):
    config = dataclasses.replace(tiny_train_config, head="idm")
    train_drivers(3, tmp_path / "out", data_dir=fake_ngsim, config=config)
    net = load_driver_net(tmp_path / "out" / "driver_net.npz")
    assert net.head_kind == "idm"
    assert net.idm is not None and bool((net.idm.log_factors != 0).any())
    saved = json.loads((tmp_path / "out" / "training_report.json").read_text())
    assert saved["config"]["head"] == "idm"
