"""Finite-element kernels: beam element, assembly."""

from .assembly import Assembler, Pattern, assemble_reference
from .beam import element_response, local_stiffness, prestrain_forces

__all__ = ["Assembler", "Pattern", "assemble_reference", "element_response",
           "local_stiffness", "prestrain_forces"]
