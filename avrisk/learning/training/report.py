"""What :func:`~avrisk.learning.training.train.train_drivers` writes and reports.

The run's outputs in its folder: the network (:data:`DRIVER_NET_FILE`), the
``xi`` prior (:data:`XI_PRIOR_FILE`) and a JSON :class:`TrainingReport` of
what the run did and measured (:data:`TRAINING_REPORT_FILE`), written by
:func:`write_training_outputs`.
"""

from __future__ import annotations

import json
import platform
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch

from avrisk.agents.drivers.network import DriverNet
from avrisk.agents.drivers.store import DRIVER_NET_FILE, XI_PRIOR_FILE, XiPrior

__all__ = [
    "KERNEL_PINS",
    "TRAINING_REPORT_FILE",
    "TrainingReport",
    "cpu_kernels",
    "training_environment",
    "write_training_outputs",
]

#: The report's file name in the output folder.
TRAINING_REPORT_FILE = "training_report.json"


@dataclass(frozen=True)
class TrainingReport:
    """What the driver training did and measured (JSON).

    Written by :func:`~avrisk.learning.training.train.train_drivers`.

    Attributes
    ----------
    seed : int
    out_dir : str
    files : dict of str to int
        Written files and their sizes [bytes].
    data : dict
        Input files (sha256) and demonstrations per source.
    trunk_history : list of dict
        Per epoch: training loss, validation NLL per source and target.
    dagger_history : list of dict
        Per DAgger round: rows added and the last refit epoch's losses.
    closed_loop_history : list of dict
        Per validation of the closed-loop stage: the minibatch's loss parts
        and the validation windows'
        (:func:`~avrisk.learning.training.closed_loop.closed_loop_finetune`).
    head_history : list of dict
        Per head epoch: mean training loss over the heads.
    validation : dict
        Validation NLL of the shared head and of ``mu0``, per source/target.
    calibration : dict
        Sampling-noise scale chosen on replays of training windows, and the
        distances of every candidate.
    prior : dict
        The prior's metadata: the graphical-lasso fit
        (:meth:`~avrisk.learning.prior.glasso.SparseGaussianFit.to_meta`) and more.
    config : dict
    environment : dict
        Versions and thread count.
    seconds : dict of str to float
        Wall time per stage.
    selection : dict or None
        With ``candidates > 1``: the criterion, every candidate's score
        (:class:`~avrisk.learning.training.selection.CandidateScore`) and the seed
        kept; None for a single training.
    """

    seed: int
    out_dir: str
    files: dict[str, int]
    data: dict[str, Any]
    trunk_history: list[dict[str, float]]
    dagger_history: list[dict[str, float]]
    closed_loop_history: list[dict[str, float]]
    head_history: list[dict[str, float]]
    validation: dict[str, Any]
    calibration: dict[str, Any]
    prior: dict[str, Any]
    config: dict[str, Any]
    environment: dict[str, Any]
    seconds: dict[str, float] = field(default_factory=dict)
    selection: dict[str, Any] | None = None

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict."""
        return asdict(self)


#: Environment variables that select the CPU kernels which trained the
#: shipped files, for torch and for OpenBLAS (numpy's and scipy's): both are
#: read when the library first needs them, so they are set before the
#: process starts.
KERNEL_PINS = {"ATEN_CPU_CAPABILITY": "avx2", "OPENBLAS_CORETYPE": "Haswell"}


def cpu_kernels() -> dict[str, Any]:
    """The CPU kernels torch and the loaded BLAS libraries dispatch to here.

    The same code, seed and thread count give other floating-point results
    with other kernels: torch's AVX-512 kernels move the closed-loop stage's
    losses against the AVX2 kernels of a CPU without AVX-512, and OpenBLAS's
    SkylakeX kernels move the graphical lasso's precision against its Haswell
    ones (BENCHMARKS.md, "Reproducing the shipped drivers: CPU kernels").

    Returns
    -------
    dict
        ``"torch"``: ``torch.backends.cpu.get_cpu_capability()`` (e.g.
        ``"AVX2"``, ``"AVX512"``); ``"blas"``: the sorted architectures of
        the BLAS libraries loaded (e.g. ``["Haswell"]``).
    """
    from threadpoolctl import threadpool_info

    blas = {i["architecture"] for i in threadpool_info() if i.get("architecture")}
    return {"torch": torch.backends.cpu.get_cpu_capability(), "blas": sorted(blas)}


def training_environment() -> dict[str, Any]:
    """Versions, torch's thread count, the machine and its CPU kernels."""
    import sklearn

    return {
        "python": platform.python_version(),
        "torch": torch.__version__,
        "numpy": np.__version__,
        "scikit-learn": sklearn.__version__,
        "torch_threads": torch.get_num_threads(),
        "machine": platform.machine(),
        "cpu_kernels": cpu_kernels(),
    }


def write_training_outputs(
    out: Path, net: DriverNet, prior: XiPrior, report: TrainingReport
) -> TrainingReport:
    """Write the network, the prior and the report (with the files' sizes) to ``out``.

    Parameters
    ----------
    out : Path
        An existing folder; files of the same names are replaced.
    net : DriverNet
    prior : XiPrior
    report : TrainingReport
        Its ``files`` are replaced by the written files and their sizes.

    Returns
    -------
    TrainingReport
        As written.
    """
    net.save(out / DRIVER_NET_FILE)
    prior.save(out / XI_PRIOR_FILE)
    files = {f: (out / f).stat().st_size for f in (DRIVER_NET_FILE, XI_PRIOR_FILE)}
    report = replace(report, files=files)
    (out / TRAINING_REPORT_FILE).write_text(json.dumps(report.to_dict(), indent=2))
    return report
