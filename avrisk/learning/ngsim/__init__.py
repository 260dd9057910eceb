"""The NGSIM data: where the files are, their loaders, and what is read off them.

* :mod:`~avrisk.learning.ngsim.files` -- where the files are (names of the
  original and packed forms, the shipped folder, ``$AVRISK_NGSIM_DIR``);
* :mod:`~avrisk.learning.ngsim.loaders` -- loaders of the data sets, in SI
  units, and the train/test split of the lateral pairs;
* :mod:`~avrisk.learning.ngsim.packed` -- the packed Parquet form, and reading
  columns of either form;
* :mod:`~avrisk.learning.ngsim.samples` -- the loaded data sets: column
  dataclasses, episodes;
* :mod:`~avrisk.learning.ngsim.lateral` -- lane centres, lateral offsets,
  headings and steering from the lateral positions;
* :mod:`~avrisk.learning.ngsim.lane_changes` -- the lane-change detector that
  serves the data and the simulator's traces alike;
* :mod:`~avrisk.learning.ngsim.us101_lane_changes` -- the US-101 lane changes:
  held-out split, the two shipped tables, rates.

Nothing here imports the rest of :mod:`avrisk.learning`.
"""
