"""Exponential families for the base distribution and the CE proposals."""

from avrisk.rare.families.base import ExponentialFamily
from avrisk.rare.families.beta import ScaledBeta
from avrisk.rare.families.normal import FixedCovNormal, box_qp
from avrisk.rare.families.product import Product
from avrisk.rare.families.standard_space import StandardSpaceShift

__all__ = [
    "ExponentialFamily",
    "FixedCovNormal",
    "Product",
    "ScaledBeta",
    "StandardSpaceShift",
    "box_qp",
]
