"""``P0(xi)``: the bootstrap ensemble of heads and the sparse Gaussian fitted to it.

* :mod:`~avrisk.learning.prior.bootstrap_heads` -- the last layer refitted on
  bootstrap resamples, trunk frozen;
* :mod:`~avrisk.learning.prior.glasso` -- Ledoit-Wolf + graphical lasso fit of
  a sparse precision;
* :mod:`~avrisk.learning.prior.xi_prior_fit` -- ``P0(xi)`` fitted to the heads,
  and the validation NLLs.
"""
