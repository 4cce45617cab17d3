"""Geometry generators: verification lattices (and, later, textiles)."""

from .lattices import GENERATORS, LatticeCell, honeycomb, lattice_frame

__all__ = ["GENERATORS", "LatticeCell", "honeycomb", "lattice_frame"]
