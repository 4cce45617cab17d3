"""A 2-periodic cell pressed between two rigid planes with its nodes tied to them (linear):
``compression_modulus``. Real contact (nodes leaving or reaching a plate) is
:func:`homtex.compress`."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..config import option
from ..errors import InputError
from ..fem.assembly import Assembler
from ..linalg.nullspace import rigid_body_modes
from ..linalg.solvers import LinearSolver, SolveReport, constrain
from ..model.frame import Frame
from ..model.topology import check_held
from .periodic import cell_measure

__all__ = ["CompressionResult", "compression_modulus"]


@dataclass
class CompressionResult:
    """A 2-periodic cell compressed between two rigid planes (nodes tied to them).

    modulus : effective compression modulus, MPa (force per area / (compression / thickness)).
    stiffness : force per compression displacement, N/mm.
    force_per_area : compressive stress at the imposed ``strain``, MPa.
    strain : imposed compression (plate approach / thickness), 1.
    thickness : plate distance, mm; area : cell area, mm^2.
    bottom, top : indices of the nodes tied to the planes.
    u : (n, 6) displacement; report : SolveReport.
    """

    modulus: float
    stiffness: float
    force_per_area: float
    strain: float
    thickness: float
    area: float
    bottom: np.ndarray
    top: np.ndarray
    planes: tuple
    u: np.ndarray
    report: SolveReport


def compression_modulus(frame: Frame, *, solver: str | None = None, tol: float | None = None,
                        tie: str = "xyz", strain: float = 1e-3, plane_tol: float | None = None,
                        maxiter: int | None = None) -> CompressionResult:
    """Effective compression modulus of a 2-periodic cell between two rigid planes in z.

    The planes touch the cell: the bottom plane at min(z - r_c), the top plane at
    max(z + r_c) over the nodes (r_c: the largest contact radius of the elements at a
    node). Nodes within ``plane_tol`` (default 1e-6 times the thickness) of a plane are
    tied to it: all translations (``tie="xyz"``, bonded) or only uz (``tie="z"``,
    frictionless; then one node's in-plane translations are pinned). The top plane
    moves down by ``strain`` times the thickness; the in-plane macro strain is zero
    (periodic fluctuations). Linear: the modulus does not depend on ``strain``.
    Real contact (nodes leaving or reaching a plane) is done by :mod:`homtex.contact`.

    Returns
    -------
    CompressionResult with the modulus (MPa) and the force per area (MPa).
    """
    if not isinstance(frame, Frame):
        raise InputError(f"frame must be a homtex.Frame, got {type(frame).__name__}")
    if frame.dim_periodic != 2 or np.abs(frame.periods[:, 2]).max() > 1e-9 * np.abs(frame.periods).max():
        raise InputError("compression_modulus needs a 2-periodic frame with lattice vectors in the "
                         "x-y plane")
    solver = option("homogenize_solver", solver)
    tol = option("tol", tol)
    if tie not in ("xyz", "z"):
        raise InputError(f"tie must be 'xyz' or 'z', got {tie!r}")
    if not (np.isfinite(strain) and 0 < strain < 1):
        raise InputError(f"strain must be in (0, 1), got {strain}")
    n = frame.n_nodes
    rc = np.zeros(n)
    np.maximum.at(rc, frame.elements[:, 0], frame.contact_radius)
    np.maximum.at(rc, frame.elements[:, 1], frame.contact_radius)
    z = frame.nodes[:, 2]
    zb = float(np.min(z - rc))
    zt = float(np.max(z + rc))
    thick = zt - zb
    ptol = 1e-6 * thick if plane_tol is None else float(plane_tol)
    bottom = np.flatnonzero(z - rc <= zb + ptol)
    top = np.flatnonzero(z + rc >= zt - ptol)
    if np.intersect1d(bottom, top).size:
        raise InputError(f"compression_modulus: nodes {np.intersect1d(bottom, top)[:10].tolist()} touch "
                         f"both planes (the cell is flat)")
    mask = np.zeros((n, 6), dtype=bool)
    vals = np.zeros((n, 6))
    delta = strain * thick
    if tie == "xyz":
        mask[bottom, :3] = True
        mask[top, :3] = True
    else:
        mask[bottom, 2] = True
        mask[top, 2] = True
        mask[bottom[0], :2] = True
    vals[top, 2] = -delta
    mask = mask.ravel()
    vals = vals.ravel()
    check_held(frame, mask)
    asm = Assembler(frame)
    K = asm.stiffness()
    b = -(K @ vals)
    A = constrain(K, mask)
    b[mask] = A.diagonal()[mask] * vals[mask]
    B = rigid_body_modes(frame.nodes) if solver == "amg" else None
    lin = LinearSolver(A, method=solver, B=B, tol=tol, maxiter=maxiter)
    x, rep = lin.solve(b)
    x[mask] = vals[mask]
    react = (K @ x).reshape(n, 6)
    force = -float(react[top, 2].sum())  # compressive force on the top plane, N
    area = cell_measure(frame)
    return CompressionResult(modulus=force / area / strain, stiffness=force / delta,
                             force_per_area=force / area, strain=strain, thickness=thick,
                             area=area, bottom=bottom, top=top, planes=(zb, zt),
                             u=x.reshape(n, 6), report=rep)
