"""Safety measures: what makes a rollout dangerous (minimum ray TTC)."""

from avrisk.safety.base import (
    SafetyMeasure,
    get_safety_measure,
    register_safety_measure,
)
from avrisk.safety.ttc import MinTTC, ray_ttc

__all__ = [
    "MinTTC",
    "SafetyMeasure",
    "get_safety_measure",
    "ray_ttc",
    "register_safety_measure",
]
