"""Tensor helpers shared by the simulator, the actors and the safety measures.

A leaf layer: it imports nothing from avrisk.

* :mod:`~avrisk.tensors.tensors` -- :class:`TensorDataclass`, the base of
  frozen dataclasses of same-shape tensors (states, parameters, actions);
* :mod:`~avrisk.tensors.noise` -- counter-based random numbers, a pure
  function of (seed, step, stream, index), so that a rollout gets the same
  noise alone or in any batch;
* :mod:`~avrisk.tensors.rows` -- some rows of a batch replaced in nested
  containers of tensors (rollouts restarted while the others go on);
* :mod:`~avrisk.tensors.slices` -- eager work on a CPU in cache-sized slices
  of the batch (the whole batch on a GPU or compiled);
* :mod:`~avrisk.tensors.mathops` -- elementary functions from IEEE basic
  operations only, bit-identical on any batch, device or compiler.
"""
