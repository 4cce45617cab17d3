"""What solves return: the energy split, static results, and the one status enumeration.

Every curve or profile that can end early carries ``attrs["status"]`` (a :class:`Status`
value) and, when not ok, ``attrs["status_detail"]`` (where and why it stopped); studies
record the same enumeration per point.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # pragma: no cover
    from ..linalg.solvers import SolveReport
    from .frame import Frame

__all__ = ["ENERGY_KEYS", "ENERGY_LONG_NAMES", "StaticResult", "Status", "set_status"]

#: strain-energy split of beam elements (N mm), in the order of the element kernels
ENERGY_KEYS = ("axial", "torsion", "bending_y", "bending_z", "shear")
ENERGY_LONG_NAMES = {"axial": "axial strain energy", "torsion": "torsional strain energy",
                     "bending_y": "bending strain energy about local y",
                     "bending_z": "bending strain energy about local z", "shear": "shear strain energy"}


class Status(str, enum.Enum):
    """Outcome of a computation that runs in steps (a curve, a profile, a study point).

    ``OK``: everything asked for was done. ``FAILED``: it stopped at a failure; the Dataset
    holds what was done before it (maybe nothing) and ``attrs["status_detail"]`` says where
    and why. ``FLAGGED``: everything asked for was done, but a check of the result failed
    (a large-motion compression curve whose stabilisation absorbed more than 1 % of the
    external work, or whose energy balance is off by more than 1 %); ``status_detail`` says
    which, and studies count it as failed. ``NOT_RUN``: a study point that has not run yet.
    """

    OK = "ok"
    FAILED = "failed"
    FLAGGED = "flagged"
    NOT_RUN = "not_run"

    @property
    def code(self) -> int:
        """Integer code of a study's ``status`` variable (0 ok, 1 failed, 2 flagged, -1 not run)."""
        return {"ok": 0, "failed": 1, "flagged": 2, "not_run": -1}[self.value]

    def __str__(self) -> str:
        return self.value


def set_status(ds, status: Status | str, detail: str = ""):
    """Set ``attrs["status"]`` (and ``status_detail`` when not ok) of a Dataset; returns it."""
    status = Status(status)
    ds.attrs["status"] = status.value
    if status is Status.OK:
        ds.attrs.pop("status_detail", None)
    else:
        ds.attrs["status_detail"] = str(detail)
    return ds


@dataclass
class StaticResult:
    """Result of a static solve.

    Attributes
    ----------
    u : (n, 6) displacements (mm) and rotations (rad) per node.
    report : SolveReport of the linear solve.
    forces : (m, 12) local end forces on each element [N, Vy, Vz, T, My, Mz] x 2 ends (N, N mm).
    energy : dict of (m,) strain energies (N mm): axial, torsion, bending_y, bending_z, shear.
    reactions : (n, 6) support reactions (zero where nothing is constrained).
    contacts : the contact state (:class:`homtex.contact.constraints.ContactSet`) of a contact solve.
    extra : solver statistics (contact iterations, timings, plate forces, ...).
    """

    frame: Frame
    u: np.ndarray
    report: SolveReport
    forces: np.ndarray
    energy: dict
    reactions: np.ndarray
    contacts: object = None
    extra: dict = field(default_factory=dict)

    @property
    def axial_force(self) -> np.ndarray:
        """(m,) axial force, tension positive, N."""
        return self.forces[:, 6]

    @property
    def total_energy(self) -> float:
        """Total strain energy, N mm."""
        return float(sum(v.sum() for v in self.energy.values()))
