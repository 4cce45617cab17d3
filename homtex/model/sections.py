"""Cross sections and materials of beam elements.

All quantities in mm and MPa. A section is described per element by two
semi-axes ``a`` (along the local e2 axis) and ``b`` (along e3); a circle has
``a == b == radius``.

Section properties (per element, arrays of shape (m,)):

* ``A``  = pi a b                          area, mm^2
* ``Iy`` = pi a b^3 / 4                    second moment about e2 (bending in the e1-e3 plane), mm^4
* ``Iz`` = pi a^3 b / 4                    second moment about e3 (bending in the e1-e2 plane), mm^4
* ``J``  = pi a^3 b^3 / (a^2 + b^2)         torsion constant (Saint-Venant, exact for the ellipse), mm^4
* ``k``  = 6 (1 + nu) / (7 + 6 nu)          shear correction factor (Cowper 1966, circle; used for
                                            the ellipse as well, an approximation there)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: default elastic limit of an element's axial and shear strain (see :class:`homtex.Frame`): polyester
#: and polyamide fibres leave their linear range at about 1.5-3 % strain, and at 2 % the small-strain
#: element's engineering strain is 1 % off a finite-strain rod's Green-Lagrange strain
DEFAULT_STRAIN_LIMIT = 0.02


def shear_factor(nu):
    """Cowper's shear correction factor of a solid circle, k = 6(1+nu)/(7+6nu)."""
    nu = np.asarray(nu, dtype=float)
    return 6.0 * (1.0 + nu) / (7.0 + 6.0 * nu)


def section_properties(a, b, nu):
    """Area and inertia of elliptical (a != b) or circular (a == b) sections.

    Parameters
    ----------
    a, b : array (m,)
        Semi-axes along local e2 and e3, mm.
    nu : array (m,)
        Poisson's ratio (for the shear correction factor).

    Returns
    -------
    dict with A, Iy, Iz, J, k as (m,) float64 arrays.
    """
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    A = np.pi * a * b
    Iy = np.pi * a * b**3 / 4.0
    Iz = np.pi * a**3 * b / 4.0
    J = np.pi * a**3 * b**3 / (a**2 + b**2)
    k = shear_factor(nu) * np.ones_like(a)
    return {"A": A, "Iy": Iy, "Iz": Iz, "J": J, "k": k}


@dataclass(frozen=True)
class YarnType:
    """A yarn: section, elastic constants and contact radius.

    Attributes
    ----------
    name : str
    radius : float
        Section radius, mm (circle) - or ``semi_axes=(a, b)`` for an ellipse.
    E : float
        Young's modulus, MPa.
    nu : float
        Poisson's ratio.
    contact_radius : float or None
        Radius used by contact, mm; defaults to the section radius (or the larger semi-axis).
    semi_axes : tuple or None
        (a, b) semi-axes of an elliptical section, mm.
    bending_factor, torsion_factor : float
        Bending and torsional rigidity relative to the solid section (see :class:`homtex.Frame`),
        default 1.
    strain_limit : float
        Largest axial or shear strain the yarn is trusted to stay elastic (default
        :data:`DEFAULT_STRAIN_LIMIT` = 0.02); the large-rotation solver warns beyond it.
    source : str
        Where the values come from (literature reference or "assumption").
    """

    name: str
    radius: float
    E: float
    nu: float
    contact_radius: float | None = None
    semi_axes: tuple | None = None
    source: str = ""
    bending_factor: float = 1.0
    torsion_factor: float = 1.0
    strain_limit: float = DEFAULT_STRAIN_LIMIT

    @property
    def a(self) -> float:
        return float(self.semi_axes[0]) if self.semi_axes else float(self.radius)

    @property
    def b(self) -> float:
        return float(self.semi_axes[1]) if self.semi_axes else float(self.radius)

    @property
    def rc(self) -> float:
        if self.contact_radius is not None:
            return float(self.contact_radius)
        return max(self.a, self.b)


def yarn_fields(types, which) -> dict:
    """Per-element :class:`~homtex.Frame` arguments of elements made of yarn types:
    element e is made of ``types[which[e]]``. Returns {semi_axes (m, 2), E, nu, contact_radius,
    bending_factor, torsion_factor, strain_limit (m,)} (mm, MPa, 1)."""
    which = np.asarray(which, dtype=np.int64)
    table = {
        "semi_axes": np.array([[t.a, t.b] for t in types], dtype=float).reshape(-1, 2),
        "E": np.array([t.E for t in types], dtype=float),
        "nu": np.array([t.nu for t in types], dtype=float),
        "contact_radius": np.array([t.rc for t in types], dtype=float),
        "bending_factor": np.array([t.bending_factor for t in types], dtype=float),
        "torsion_factor": np.array([t.torsion_factor for t in types], dtype=float),
        "strain_limit": np.array([t.strain_limit for t in types], dtype=float),
    }
    return {k: np.ascontiguousarray(v[which]) for k, v in table.items()}
