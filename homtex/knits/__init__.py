"""Weft-knitted fabrics: relaxed cells (:func:`relax`), tensile tests of the periodic cell and of a
finite specimen (:func:`tensile`), the energy split of the knit paper and the m / l^3 scaling."""

from .relax import RelaxedCell, relax
from .tensile import tensile

__all__ = ["RelaxedCell", "relax", "tensile"]
