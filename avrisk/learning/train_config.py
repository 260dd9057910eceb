"""What the driver training is told, and what it reports.

:class:`TrainConfig` holds the settings of every stage of
:func:`~avrisk.learning.training.train.train_drivers` (the defaults made the
shipped files); every stage reports its progress in :class:`TrainEvent`
reports to an optional :data:`Progress` callback (the CLI draws them as
progress bars).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import NamedTuple

from avrisk.agents.drivers.guard import BrakeGuard
from avrisk.agents.drivers.idm_head import check_head

__all__ = ["ClosedLoopConfig", "Progress", "TrainConfig", "TrainEvent"]


@dataclass(frozen=True)
class ClosedLoopConfig:
    """Settings of :func:`closed_loop_finetune`.

    Parameters
    ----------
    iterations : int, default=120
        Adam steps (0 skips the stage).
    batch_windows : int, default=64
        Training windows replayed per step.
    window_steps : int, default=150
        Steps per window (15 s), back-propagated through in full.
    lr : float, default=3e-4
        Adam learning rate.
    hard_brake_decel : float, default=-2.0
        A training window whose leader brakes harder than this at some step
        [m/s^2] is a hard-braking window (about 8% of the I-80 training
        windows; 6 of 1,066 also stop the leader after braking harder than
        -2.5 m/s^2).
    hard_brake_oversample : float, default=1.0
        Hard-braking windows are drawn this many times as often as the others
        into the minibatches (1: uniform draws).
    congested_share : float or None, default=None
        Share of the minibatch draws that come from congested windows
        (:func:`~avrisk.learning.replay.window_bands`: leader's mean speed
        below 5 m/s), each band's windows drawn alike within it (and
        ``hard_brake_oversample`` within that); None: as the training windows
        hold them (periods differ widely in that mix: BENCHMARKS.md, "Drivers
        on a period they never saw"). A rule on the training windows' own
        records, for traffic whose mix of bands is not the training period's.
    gap_margin : float, default=2.0
        Gap below which the safety barrier acts [m] (humans' 5th percentile
        of the gap in the training windows is about 2.6 m).
    safety_weight : float, default=1.0
        Weight of the barrier [1/m^2].
    ttc_margin : float, default=1.0
        Time to collision below which a second barrier acts [s]: ``(closing
        speed - gap / ttc_margin)_+^2`` [m^2/s^2] per step while in line. It
        grows while the follower closes in fast, before the gap is short (0:
        off). Chosen with the shipped recipe (BENCHMARKS.md, "Training on top
        of the brake").
    ttc_weight : float, default=10.0
        Weight of the TTC barrier [s^2/m^2].
    imitation_weight : float, default=1.0
        Weight of the speed and gap imitation terms (0: the recorded
        trajectories are not imitated, only matched in distribution through
        ``adversarial_weight``).
    offset_weight : float, default=1.0
        Weight of the lane-offset imitation term (lateral windows).
    adversarial_weight : float, default=10.0
        Weight of MGAIL's reward (:mod:`avrisk.learning.imitation.mgail`): the loss
        gets ``-adversarial_weight`` times the mean discriminator reward of the
        simulated transitions (0: no discriminator).
    disc_hidden : int, default=64
        Width of the discriminator's hidden layers.
    disc_lr : float, default=1e-3
        Adam learning rate of the discriminator.
    disc_epochs : int, default=2
        Passes of the discriminator over the minibatch's transitions per step.
    disc_batch : int, default=2048
        Transitions of each class per discriminator step.
    validation_fraction : float, default=0.2
        Training windows held out for early stopping (on the loss without
        its adversarial term, whose discriminator moves).
    validate_every : int, default=10
        Steps between validations.
    grad_clip : float, default=1.0
        Maximal gradient norm per step.
    stress_windows : int, default=16
        Hard-braking training windows replayed per step besides the
        minibatch with their leaders braking ``stress_factor`` times as hard
        (:func:`~avrisk.learning.training.closed_loop.stressed`), under the barriers
        alone (the recorded follower no longer belongs to them): emergencies
        harder than the data hold, in which to learn to stop (0: none).
    stress_factor : float, default=1.5
        How much harder their leaders brake.
    stress_own_noise : bool, default=False
        Give the stress replays action noise of their own. False, as when
        the shipped files were trained, reuses the noise seeds of minibatch
        windows 7, 8, ..., so that the stress replays share those windows'
        noise streams. True did not reduce the held-out collisions
        (BENCHMARKS.md, "Keeping the safest of several trainings", recipe
        (q)).
    drive_with_guard : bool, default=True
        The minibatch and validation replays drive with the emergency brake
        the weights will carry (:attr:`TrainConfig.guard`): the network
        learns to follow as the braked driver will drive. The stress replays
        drive the network alone, so that it still learns to stop in their
        emergencies by itself. False trains the network alone everywhere.
    """

    iterations: int = 120
    batch_windows: int = 64
    window_steps: int = 150
    lr: float = 3e-4
    hard_brake_decel: float = -2.0
    hard_brake_oversample: float = 1.0
    congested_share: float | None = None
    gap_margin: float = 2.0
    safety_weight: float = 1.0
    ttc_margin: float = 1.0
    ttc_weight: float = 10.0
    imitation_weight: float = 1.0
    offset_weight: float = 1.0
    adversarial_weight: float = 10.0
    disc_hidden: int = 64
    disc_lr: float = 1e-3
    disc_epochs: int = 2
    disc_batch: int = 2048
    validation_fraction: float = 0.2
    validate_every: int = 10
    grad_clip: float = 1.0
    stress_windows: int = 16
    stress_factor: float = 1.5
    stress_own_noise: bool = False
    drive_with_guard: bool = True

    def __post_init__(self) -> None:
        if (
            self.iterations < 0
            or min(
                self.batch_windows,
                self.window_steps,
                self.validate_every,
                self.disc_hidden,
                self.disc_epochs,
                self.disc_batch,
            )
            < 1
        ):
            raise ValueError(
                "iterations must be >= 0 and batch_windows, window_steps, "
                "validate_every and the disc_ sizes >= 1"
            )
        if self.stress_windows < 0 or self.stress_factor < 1.0:
            raise ValueError(
                "stress_windows must be >= 0 and stress_factor >= 1; got "
                f"{self.stress_windows} and {self.stress_factor}"
            )
        share = self.congested_share
        if share is not None and not 0.0 < share < 1.0:
            raise ValueError(f"congested_share must be in (0, 1); got {share}")
        if self.hard_brake_oversample < 1.0:
            raise ValueError(
                f"hard_brake_oversample must be >= 1; got {self.hard_brake_oversample}"
            )
        weights = ("ttc_margin", "ttc_weight", "imitation_weight", "adversarial_weight")
        for name in weights:
            if getattr(self, name) < 0:
                raise ValueError(f"{name} must be >= 0; got {getattr(self, name)}")
        if not 0.0 < self.validation_fraction < 1.0:
            raise ValueError(
                f"validation_fraction must be in (0, 1); got {self.validation_fraction}"
            )


@dataclass(frozen=True)
class TrainConfig:
    """Settings of :func:`~avrisk.learning.training.train.train_drivers`.

    The defaults made the shipped files.

    Parameters
    ----------
    n_members : int, default=20
        Ensemble heads ``m``.
    trunk_epochs : int, default=12
        Behaviour-cloning epochs of the whole network.
    head_epochs : int, default=20
        Epochs of every bootstrap head (trunk frozen).
    batch_size : int, default=1024
        Rows per step of behaviour cloning.
    head_batch_size : int, default=4096
        Rows per step of the heads.
    lr : float, default=1e-3
        Adam learning rate of behaviour cloning.
    head_lr : float, default=3e-4
        Adam learning rate of the heads.
    weight_decay : float, default=1e-5
        Adam weight decay.
    n_sim_rollouts : int, default=256
        IDM+MOBIL rollouts for training demonstrations (8 vehicles, 15 s).
    n_sim_val_rollouts : int, default=32
        IDM+MOBIL rollouts for validation (another seed).
    sim_accel_weight : float, default=0.25
        Loss weight of the simulated (non-human) acceleration targets.
    dagger_iters : int, default=4
        DAgger rounds after behaviour cloning (0: plain behaviour cloning).
    dagger_rollouts : int, default=128
        Learner rollouts per round in random traffic (8 vehicles, 15 s).
    dagger_windows : int, default=0
        Learner replays per round of human car-following training windows
        (15 s), labelled by IDM
        (:func:`avrisk.learning.imitation.dagger.replay_dagger_demonstrations`). Off by
        default: with 256 per round the IDM labels contradicted the human ones
        on nearly the same states and closed-loop realism got worse.
    dagger_epochs : int, default=3
        Refit epochs per round, on all demonstrations so far.
    dagger_lr : float, default=5e-4
        Adam learning rate of the refits.
    dagger_accel_weight : float, default=0.5
        Loss weight of the expert's acceleration labels on visited states (the
        human data have no emergency braking; only the expert shows it).
    calibration_windows : int, default=160
        Training car-following windows replayed to calibrate the sampling
        noise
        (:func:`avrisk.learning.training.sampling_noise.calibrate_noise`); 0
        skips it and keeps the network's own Gaussian (``noise_scale = 1``).
    calibration_steps : int, default=100
        Steps per calibration window.
    target_density : float, default=0.01
        Graphical lasso: fraction of coordinate pairs that may be linked.
    max_shift : float, default=0.01
        CE search box of the ``xi`` block, recorded in the prior's metadata.
    closed_loop : ClosedLoopConfig
        Closed-loop training after DAgger and the noise calibration
        (:mod:`avrisk.learning.training.closed_loop`; ``iterations=0`` skips it).
    guard : BrakeGuard or None, default=BrakeGuard(2.0, 2.0, hold_floor=True)
        The emergency brake written with the weights
        (:mod:`avrisk.agents.drivers.guard`): the scenarios' environment
        drivers and ``avrisk realism`` drive with it, and ``--candidates``
        scores with it; the closed loop's minibatch and validation replays
        drive with it when ``closed_loop.drive_with_guard``. It acts only
        where stopping the closing 2 m short of the vehicle ahead needs more
        than 2 m/s^2, or while closing inside those 2 m: an emergency brake
        that leaves the following gaps and times to collision to the network
        (BENCHMARKS.md, "Training on top of the brake"). None writes drivers
        without one.
    periods : tuple of str or None, default=None
        The I-80 recording periods trained on (the pairs file's ``period``
        values, e.g. ``("0400pm-0415pm",)``); None: all. The lateral file
        (16:00-16:15) is read only when its period is among them. For
        leave-one-period-out validation (:mod:`avrisk.realism.held_out`).
    head : {"free", "idm"}, default="free"
        The network's acceleration head
        (:class:`~avrisk.agents.drivers.network.DriverNet`): the mean
        acceleration itself, or the factor on the IDM's desired gap
        (:mod:`avrisk.agents.drivers.idm_head`).
    """

    n_members: int = 20
    trunk_epochs: int = 12
    head_epochs: int = 20
    batch_size: int = 1024
    head_batch_size: int = 4096
    lr: float = 1e-3
    head_lr: float = 3e-4
    weight_decay: float = 1e-5
    n_sim_rollouts: int = 256
    n_sim_val_rollouts: int = 32
    sim_accel_weight: float = 0.25
    dagger_iters: int = 4
    dagger_rollouts: int = 128
    dagger_windows: int = 0
    dagger_epochs: int = 3
    dagger_lr: float = 5e-4
    dagger_accel_weight: float = 0.5
    calibration_windows: int = 160
    calibration_steps: int = 100
    target_density: float = 0.01
    max_shift: float = 0.01
    closed_loop: ClosedLoopConfig = field(default_factory=ClosedLoopConfig)
    guard: BrakeGuard | None = BrakeGuard(2.0, 2.0, hold_floor=True)
    periods: tuple[str, ...] | None = None
    head: str = "free"

    def __post_init__(self) -> None:
        check_head(self.head)
        if self.periods is not None and not self.periods:
            raise ValueError("periods must name at least one period (None: all)")
        if self.n_members < 2:
            raise ValueError(f"n_members must be >= 2; got {self.n_members}")
        for name in ("trunk_epochs", "head_epochs", "batch_size", "head_batch_size"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be >= 1; got {getattr(self, name)}")
        if self.closed_loop.drive_with_guard and self.guard is None:
            raise ValueError("closed_loop.drive_with_guard needs a guard to drive with")


class TrainEvent(NamedTuple):
    """One progress report of a training stage.

    Attributes
    ----------
    stage : str
        ``"data"``, ``"trunk"``, ``"dagger"``, ``"noise"``, ``"closed_loop"``,
        ``"heads"`` or ``"prior"``.
    step : int
        Steps of the stage done.
    total : int
        Steps of the stage.
    metrics : dict of str to float
        E.g. the training loss and validation NLLs.
    """

    stage: str
    step: int
    total: int
    metrics: dict[str, float]


Progress = Callable[[TrainEvent], None]
