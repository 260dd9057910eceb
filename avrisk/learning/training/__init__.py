"""The driver training: its stages in order, its inputs and its outputs.

* :mod:`~avrisk.learning.training.train` -- :func:`train_drivers
  <avrisk.learning.training.train.train_drivers>`, every stage in order, and
  the choice among several seeds;
* :mod:`~avrisk.learning.training.data` -- the training and validation
  demonstrations and car-following windows;
* :mod:`~avrisk.learning.training.sampling_noise` -- the noise's persistence
  from human residuals and its scale by replays;
* :mod:`~avrisk.learning.training.closed_loop` -- back-propagation through
  replays of training windows in the simulator's own step;
* :mod:`~avrisk.learning.training.selection` -- the safest of several
  trainings, chosen on training data alone;
* :mod:`~avrisk.learning.training.report` -- the written files and the
  training report.

The settings and progress events of every stage are
:mod:`avrisk.learning.train_config`'s.
"""
