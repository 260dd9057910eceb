"""Scenarios as data: the YAML spec, the base distribution ``P0`` and named ``X``.

* :func:`load_spec` -- read and validate a scenario (a file or a bundled name)
  into a :class:`ScenarioSpec` (:mod:`avrisk.scenario.spec`; its parts in
  :mod:`~avrisk.scenario.scene` and :mod:`~avrisk.scenario.components`);
* :func:`build_base_distribution` -- ``P0`` as an :class:`avrisk.rare.Product`
  (:func:`xi_base_family`: its learned-driver block, from a given prior;
  :func:`noise_base_family`: their action innovations, when in ``X``);
* :class:`ParamLayout`, :class:`ScenarioParams` -- flat ``X`` (B, D) <-> named
  per-vehicle parameters.

It knows nothing of the simulator, the drivers or the safety measures:
:mod:`avrisk.assembly` turns a spec into those, and passes in what ``P0`` and
the layout need of the learned drivers (their ``xi`` prior and dimension).
"""

from avrisk.scenario.base_distribution import (
    NormalPrior,
    build_base_distribution,
    marginal_family,
    noise_base_family,
    xi_base_family,
)
from avrisk.scenario.errors import ScenarioSpecError
from avrisk.scenario.loading import (
    MAX_SPEC_BYTES,
    bundled_folder,
    bundled_scenario_text,
    bundled_scenarios,
    load_spec,
    spec_from_dict,
)
from avrisk.scenario.params import FIELD_UNITS, ParamLayout, ScenarioParams
from avrisk.scenario.scene import VEHICLE_FIELDS
from avrisk.scenario.spec import ScenarioSpec

__all__ = [
    "FIELD_UNITS",
    "MAX_SPEC_BYTES",
    "VEHICLE_FIELDS",
    "NormalPrior",
    "ParamLayout",
    "ScenarioParams",
    "ScenarioSpec",
    "ScenarioSpecError",
    "build_base_distribution",
    "bundled_folder",
    "bundled_scenario_text",
    "bundled_scenarios",
    "load_spec",
    "marginal_family",
    "noise_base_family",
    "spec_from_dict",
    "xi_base_family",
]
