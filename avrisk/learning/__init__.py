"""Learning the environment drivers and their ``xi`` distribution from data.

Modules (import them directly; this package imports nothing heavy on load),
by job:

Data sources

* :mod:`~avrisk.learning.ngsim_files` -- where the NGSIM files are (names of
  the original and packed forms, the shipped folder, ``$AVRISK_NGSIM_DIR``);
* :mod:`~avrisk.learning.ngsim` -- loaders of the NGSIM data sets, in SI
  units, and the train/test split of the lateral pairs;
* :mod:`~avrisk.learning.ngsim_packed` -- the packed Parquet form, and reading
  columns of either form;
* :mod:`~avrisk.learning.ngsim_samples` -- the loaded data sets: column
  dataclasses, episodes;
* :mod:`~avrisk.learning.ngsim_lateral` -- lane centres, lateral offsets,
  headings and steering from the lateral positions;

Demonstrations

* :mod:`~avrisk.learning.demonstrations` -- (features, action) pairs with
  weights, observed through the simulator's own observation code;
* :mod:`~avrisk.learning.ngsim_demonstrations` -- pairs from the NGSIM data;
* :mod:`~avrisk.learning.simulated_demonstrations` -- pairs from lane-keeping
  IDM drivers among IDM+MOBIL traffic in our simulator;
* :mod:`~avrisk.learning.replay` -- closed-loop replays of human car following
  (realism);

Training stages (:func:`~avrisk.learning.train.train_drivers` runs them in
order, with the settings of :mod:`~avrisk.learning.train_config`)

* :mod:`~avrisk.learning.training_data` -- the training and validation
  demonstrations and car-following windows;
* :mod:`~avrisk.learning.imitation_loss` -- the weighted Gaussian NLL;
* :mod:`~avrisk.learning.behaviour_cloning` -- behaviour cloning of a new
  network;
* :mod:`~avrisk.learning.sampling_noise` -- the noise's persistence from human
  residuals and its scale by replays;
* :mod:`~avrisk.learning.dagger` -- expert labels on the states the learned
  drivers visit, and the DAgger rounds;
* :mod:`~avrisk.learning.closed_loop` -- back-propagation through replays of
  training windows in the simulator's own step: trajectory imitation, gap and
  TTC barriers, (optional) MGAIL's discriminator reward, and replays of
  hard-braking windows made harder (``stressed``) under the barriers;
* :mod:`~avrisk.learning.mgail` -- the discriminator of that reward;
* :mod:`~avrisk.learning.bootstrap_heads` -- the bootstrap ensemble of heads;
* :mod:`~avrisk.learning.xi_prior_fit` -- ``P0(xi)`` fitted to the heads, and
  the validation NLLs;
* :mod:`~avrisk.learning.glasso` -- Ledoit-Wolf + graphical lasso fit of a
  sparse precision;
* :mod:`~avrisk.learning.training_report` -- the written files and the
  training report;

Not part of :func:`~avrisk.learning.train.train_drivers`

* :mod:`~avrisk.learning.gail` -- GAIL with PPO: fine-tunes the acceleration
  head of a trained network in replays of human car following (not used by
  the shipped weights).

What the data can and cannot teach
----------------------------------
The NGSIM files hold car-following pairs (a follower and its leader) and
single-vehicle trajectories: they give human *longitudinal* behaviour and human
lane keeping, but no lane changes with neighbours and no vehicles in other
lanes. Those demonstrations come from IDM drivers in our own simulator
(:func:`~avrisk.learning.simulated_demonstrations.simulated_demonstrations`), among
IDM+MOBIL traffic that changes lanes around them, and DAgger labels the
learner's own states with IDM as the expert: the learned drivers' reactions to
neighbours and their emergency braking are therefore IDM's, not a human's.
Their acceleration targets carry a lower loss weight than the human ones.

The learned drivers do not change lanes: a unimodal Gaussian policy of the
current state cannot represent the discrete decision (trained on MOBIL's lane
changes it drifted half-way into the next lane and sideswiped), so lane
changes are not demonstrated. The human rate (US-101, about 50 per
vehicle-hour) is not matched.

The paper's method
------------------
The paper trains its generators with model-based GAIL (Baram et al. 2017): a
discriminator reward made differentiable through a forward model. Here the
forward model is the simulator's own differentiable step:
:func:`~avrisk.learning.closed_loop.closed_loop_finetune` with
``ClosedLoopConfig(adversarial_weight > 0)`` back-propagates the
discriminator's reward (:mod:`~avrisk.learning.mgail`) through replays of
human car following into every weight of the network, with a gap and a TTC
barrier as RAIL's collision penalty. The shipped files add it to trajectory
imitation (the default ``ClosedLoopConfig``): on held-out windows that had
fewer rear-end collisions than imitation or MGAIL with the same barriers, and
with the stressed replays none at all, at the cost of longer gaps
(BENCHMARKS.md, "Learned drivers"). Model-free GAIL with PPO
(:func:`~avrisk.learning.gail.gail_finetune`, the acceleration rows of the
shared head only) is not run by ``train_drivers``; it did not reduce the
rear-end collisions. The ensemble is one trunk with ``m`` bootstrap heads
(DESIGN.md §4), not ``m`` independently trained generators.
"""
