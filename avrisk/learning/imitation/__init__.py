"""Imitation: demonstrations and the methods that fit a driver network to them.

* :mod:`~avrisk.learning.imitation.demonstrations` -- (features, action) pairs
  with weights, observed through the simulator's own observation code;
* :mod:`~avrisk.learning.imitation.ngsim_demonstrations` -- pairs from the
  NGSIM data;
* :mod:`~avrisk.learning.imitation.simulated_demonstrations` -- pairs from
  lane-keeping IDM drivers among IDM+MOBIL traffic in our simulator;
* :mod:`~avrisk.learning.imitation.loss` -- the weighted Gaussian NLL;
* :mod:`~avrisk.learning.imitation.behaviour_cloning` -- behaviour cloning of a
  new network;
* :mod:`~avrisk.learning.imitation.dagger` -- expert labels on the states the
  learned drivers visit, and the DAgger rounds;
* :mod:`~avrisk.learning.imitation.discriminator` -- the transition features
  of human and simulated car following, and the logistic training of a
  discriminator between them;
* :mod:`~avrisk.learning.imitation.mgail` -- model-based GAIL's discriminator,
  whose reward the closed-loop stage back-propagates through the simulator.
"""
