"""Contact between yarns and with rigid plates; compression tests.

Public: :class:`Contact` (options), :class:`~homtex.model.scene.Plate` (rigid plane),
:class:`ContactSolver` and :func:`solve_contact` (what ``homtex.solve_static(..., contact=...)``
runs). ``homtex.compress`` (in :mod:`homtex.api`) runs :func:`homtex.contact.compress.run_compression`.
"""

from ..model.scene import Plate
from .constraints import ContactSet
from .options import Contact
from .solver import ContactSolver, solve_contact

__all__ = ["Contact", "ContactSet", "ContactSolver", "Plate", "solve_contact"]
