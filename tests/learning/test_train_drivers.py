import json

import pytest
import torch

from avrisk.agents.drivers.store import XiPrior, load_driver_net
from avrisk.agents.drivers.xi import XI_DIM
from avrisk.learning.train import train_drivers


@pytest.mark.slow
def test_train_drivers_writes_loadable_weights_a_prior_and_a_report(
    tmp_path, fake_ngsim, tiny_train_config
):
    report = train_drivers(
        3, tmp_path / "out", data_dir=fake_ngsim, config=tiny_train_config
    )
    net = load_driver_net(tmp_path / "out" / "driver_net.npz")
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
