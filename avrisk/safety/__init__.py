"""Safety measures: what makes a rollout dangerous (minimum TTC: ray or box).

Each implements :class:`avrisk.sim.interfaces.SafetyMeasure`; importing the
package registers them by name (:func:`get_safety_measure`).
"""

from avrisk.safety.box_ttc import MinBoxTTC, box_ttc
from avrisk.safety.registry import get_safety_measure, register_safety_measure
from avrisk.safety.ttc import MinTTC, ray_ttc

__all__ = [
    "MinBoxTTC",
    "MinTTC",
    "box_ttc",
    "get_safety_measure",
    "ray_ttc",
    "register_safety_measure",
]
