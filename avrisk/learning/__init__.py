"""Learning the environment drivers and their ``xi`` distribution from data.

Subpackages and modules by stage (import the modules directly; no package
here imports anything heavy on load):

* :mod:`avrisk.learning.ngsim` -- the data: where the NGSIM files are, their
  loaders in SI units, the packed form, lane keeping and lane changes read off
  the lateral positions (imports nothing else of :mod:`avrisk.learning`);
* :mod:`avrisk.learning.replay` -- closed-loop replays of human car-following
  windows and their distances to the record (training and the realism report
  both use them);
* :mod:`avrisk.learning.imitation` -- demonstrations (NGSIM pairs and IDM
  scenes in our simulator, observed through the simulator's own observation
  code), the imitation loss, behaviour cloning, DAgger, and the discriminator
  of model-based GAIL;
* :mod:`avrisk.learning.prior` -- the bootstrap ensemble of heads and
  ``P0(xi)``, a sparse Gaussian fitted to it;
* :mod:`avrisk.learning.training` --
  :func:`~avrisk.learning.training.train.train_drivers`, which runs the stages
  in order (training data, behaviour cloning, sampling noise, DAgger, closed
  loop, bootstrap heads, ``P0(xi)``), its closed-loop stage, the choice among
  seeds, and the written files and report;
* :mod:`avrisk.learning.train_config` -- the settings of every stage and the
  progress events they report;
* :mod:`avrisk.learning.guard_fit` -- the emergency brake's settings fitted to
  the humans' closing-in;
* :mod:`avrisk.learning.vision` -- PilotNet's training on rendered images.

GAIL with PPO (fine-tuning the acceleration head of a trained network in
replays of human car following) was tried and is not shipped: it lives beside
its benchmark, in ``benchmarks/gail_ppo.py``.

What the data can and cannot teach
----------------------------------
The NGSIM files hold car-following pairs (a follower and its leader) and
single-vehicle trajectories: they give human *longitudinal* behaviour and human
lane keeping, but no lane changes with neighbours and no vehicles in other
lanes. Those demonstrations come from IDM drivers in our own simulator
(:mod:`~avrisk.learning.imitation.simulated_demonstrations`), among IDM+MOBIL
traffic that changes lanes around them, and DAgger labels the
learner's own states with IDM as the expert: the learned drivers' reactions to
neighbours and their emergency braking are therefore IDM's, not a human's.
Their acceleration targets carry a lower loss weight than the human ones.

The driver network does not change lanes: a unimodal Gaussian policy of the
current state cannot represent the discrete decision (trained on MOBIL's lane
changes it drifted half-way into the next lane and sideswiped), so lane
changes are not demonstrated. They come from a layer on top of the network
(:mod:`avrisk.agents.drivers.lane_change`), whose rate is fitted to the
US-101 training vehicles (:mod:`avrisk.learning.ngsim.us101_lane_changes`).

The paper's method
------------------
The paper trains its generators with model-based GAIL (Baram et al. 2017): a
discriminator reward made differentiable through a forward model. Here the
forward model is the simulator's own differentiable step:
:func:`~avrisk.learning.training.closed_loop.closed_loop_finetune` with
``ClosedLoopConfig(adversarial_weight > 0)`` back-propagates the
discriminator's reward (:mod:`~avrisk.learning.imitation.mgail`) through
replays of human car following into every weight of the network, with a gap
and a TTC barrier as RAIL's collision penalty. The shipped files add it to
trajectory imitation (the default ``ClosedLoopConfig``): on held-out windows
the two together had fewer rear-end collisions than either alone with the
same barriers, and fewer still with the stressed replays, at the cost of
longer gaps (BENCHMARKS.md, "Learned drivers"). Model-free GAIL with PPO
(``benchmarks/gail_ppo.py``, the acceleration rows of the shared head only) is
not run by ``train_drivers``; it did not reduce the rear-end collisions
(docs/benchmarks-history.md, "GAIL fine-tuning of the acceleration head"). The
ensemble is one trunk with ``m`` bootstrap heads, refitted with the trunk
frozen so that they are comparable, not ``m`` independently trained generators.
"""
