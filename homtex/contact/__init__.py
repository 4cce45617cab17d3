"""Contact between yarns and with rigid plates; compression tests.

Public: :class:`Contact` (options), :class:`Plate` (rigid plane), :func:`compress`
(compression curve as an xarray Dataset). ``homtex.solve_static(..., contact=Contact())``
solves a frame with contact (see :mod:`homtex.contact.solve`).
"""

from .constraints import ContactSet, Plate
from .solve import Contact, ContactSolver, solve_contact
from .compress import compress  # noqa: E402  (the function shadows the submodule name)

__all__ = ["Contact", "ContactSet", "ContactSolver", "Plate", "compress", "solve_contact"]
