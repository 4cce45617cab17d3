"""The one energy balance of every path (``solve_nonlinear`` with or without contact, ``compress``,
the seam functions, ``tensile``) and the check that flags a path whose ledger does not close.

The ledger of a path (cumulative from its start, N mm):

* ``external_work``: work of the loads and of the reactions on prescribed motions (plates too),
* ``prestrain_work``: work of the pre-strain ramp (the stitch thread pulled shorter),
* ``strain_energy`` and ``contact_energy``: changes of the stored beam and barrier energies,
* ``friction_energy``: energy dissipated by friction,
* ``stabilization_energy``: energy taken out by the solver where the state jumped (the
  pseudo-transient continuation of the contact engine, or a snap-through to the stable branch).

The balance is (external work + pre-strain work - stored changes - friction - stabilisation)
over the largest magnitude among those six terms, so that it reads as a relative error whether
the path is driven (work in) or relaxes (energy released, no driver).
"""

from __future__ import annotations

import numpy as np

__all__ = ["CHECK_LIMIT", "LEDGER_META", "balance", "energy_floor", "ledger_check"]

#: largest relative energy imbalance, and largest share of the driven work the stabilisation may
#: take, on a path reported "ok" (beyond: "flagged")
CHECK_LIMIT = 0.01

LEDGER_META = {
    "external_work": ("N mm", "work of the loads and of the reactions on prescribed motions and plates"),
    "prestrain_work": ("N mm", "work of the pre-strain ramp (integral of dU/d(pre-strain scale))"),
    "strain_energy": ("N mm", "beam strain energy minus its value at the start of the path"),
    "contact_energy": ("N mm", "barrier energy of the contacts minus its value at the start"),
    "friction_energy": ("N mm", "energy dissipated by friction since the start"),
    "stabilization_energy": ("N mm", "energy taken out where the state jumped (pseudo-transient continuation, "
                                     "snap-through), since the start"),
    "energy_balance": ("1", "(external + pre-strain work - strain - contact - friction - stabilisation energy) / "
                            "the largest of these magnitudes"),
}


def energy_floor(frame) -> float:
    """Energies below this (N mm) are round-off for ``frame``: the strain energy of an axial strain
    of about 1.4e-6 in all its elements, 1e-12 x max(EA) x total length."""
    return 1e-12 * float(np.max(frame.EA, initial=0.0)) * float(np.sum(frame.length))


def balance(external_work, prestrain_work, strain_energy, contact_energy=0.0, friction_energy=0.0,
            stabilization_energy=0.0, floor: float = 0.0):
    """Relative imbalance of the ledger (scalars or arrays of the same shape); 0 where every term
    is at most ``floor`` (N mm: round-off, see :func:`energy_floor`)."""
    terms = np.broadcast_arrays(*(np.asarray(t, dtype=float) for t in (
        external_work, prestrain_work, strain_energy, contact_energy, friction_energy, stabilization_energy)))
    w, wp, du, db, d, s = terms
    rest = w + wp - du - db - d - s
    scale = np.max(np.abs(np.stack(terms)), axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        out = np.where(scale > floor, rest / np.where(scale > 0, scale, 1.0), 0.0)
    return float(out) if out.ndim == 0 else out


def ledger_check(external_work, prestrain_work, stabilization_energy, energy_balance, levels,
                 level_name: str = "load factor", driven: bool = True, limit: float = CHECK_LIMIT,
                 floor: float = 0.0, friction_energy=None) -> str:
    """'' if the path passes, else what fails and where: the balance beyond ``limit`` at any state,
    or (``driven``: loads, motions or a pre-strain ramp did work) a stabilisation beyond ``limit``
    of the driven work (a relaxation with no driver reports what it released, unflagged);
    stabilisation at most ``floor`` (N mm, round-off) is not counted. ``friction_energy`` (the
    energy friction dissipated so far, N mm, one per state): friction that gave energy back (below
    -``limit`` of the driven work) is named with its cause."""
    W = np.abs(np.asarray(external_work, dtype=float) + np.asarray(prestrain_work, dtype=float))
    S = np.asarray(stabilization_energy, dtype=float)
    bal = np.asarray(energy_balance, dtype=float)
    lv = np.asarray(levels, dtype=float)
    msgs = []
    if driven and S.size:
        with np.errstate(divide="ignore", invalid="ignore"):
            frac = np.where(S <= floor, 0.0, np.where(W > 0, S / np.where(W > 0, W, 1.0), np.inf))
        k = int(np.nanargmax(frac))
        if frac[k] > limit:
            msgs.append(f"the stabilisation absorbed {100 * frac[k]:.3g} % of the driven work by {level_name} "
                        f"{lv[k]:.4g} (limit {100 * limit:g} %): the state jumps there (a snap-through or buckling "
                        "released energy, or a step too large)")
    if bal.size and np.nanmax(np.abs(bal)) > limit:
        k = int(np.nanargmax(np.abs(bal)))
        msgs.append(f"the energy balance is off by {100 * bal[k]:.3g} % at {level_name} {lv[k]:.4g} "
                    f"(limit {100 * limit:g} %)")
    if bal.size and not np.all(np.isfinite(bal)):
        msgs.append("the energy ledger is not finite")
    if friction_energy is not None:
        msgs.extend(_friction_check(np.asarray(friction_energy, dtype=float), W, lv, level_name, limit, floor))
    return "; ".join(msgs)


def _friction_check(D, W, lv, level_name, limit, floor) -> list:
    """The ledger's friction must dissipate: D (states,) N mm, W (states,) |driven work|."""
    if not D.size:
        return []
    bound = np.maximum(limit * np.maximum.accumulate(W), floor)
    k = int(np.argmin(D + bound))
    if D[k] + bound[k] >= 0.0:
        return []
    # the engine's friction rubs with nonnegative normal forces only (homtex.contact.friction), so
    # this guards the ledger against a law that is not (a hand-built lag, a regression)
    return [f"friction gave energy back ({D[k]:.3g} N mm dissipated by {level_name} {lv[k]:.4g}, against "
            f"{W[k]:.3g} N mm of driven work): a friction law with negative normal forces is not dissipative "
            "(docs/contact.md, 'Friction and thick yarns'); "
            "the forces of this path are not trustworthy"]


#: 3-point Gauss-Legendre rule on [0, 1] (exact for the degree-5 integrand of :func:`hermite_work`)
_GAUSS_X = 0.5 + 0.5 * np.array([-np.sqrt(0.6), 0.0, np.sqrt(0.6)])
_GAUSS_W = np.array([5.0, 8.0, 5.0]) / 18.0


def hermite_work(Fa, Fb, dU, Ta, Tb, KTa, KTb) -> float:
    """Work of the external forces along one step of an equilibrium path, N mm.

    The path between two equilibrium states is interpolated by cubic Hermite polynomials in the
    step parameter sigma in [0, 1]: the motion U(sigma) from its increment ``dU`` (6n,) and its
    end tangents ``Ta``, ``Tb`` (6n,: dU/dsigma, oriented along the step), the external force
    F(sigma) (= the internal force at equilibrium, loads and reactions) from ``Fa``, ``Fb`` and
    its rates ``KTa`` = K_a Ta, ``KTb`` = K_b Tb (the tangent stiffness times the path tangent).
    W = int F . dU/dsigma dsigma by 3-point Gauss (exact for the cubics): fourth order in the step
    where the trapezoidal rule is second order."""
    w = 0.0
    for s, g in zip(_GAUSS_X, _GAUSS_W):
        h00, h10 = 2 * s ** 3 - 3 * s ** 2 + 1, s ** 3 - 2 * s ** 2 + s
        h01, h11 = -2 * s ** 3 + 3 * s ** 2, s ** 3 - s ** 2
        d10, d01, d11 = 3 * s ** 2 - 4 * s + 1, -6 * s ** 2 + 6 * s, 3 * s ** 2 - 2 * s
        F = h00 * Fa + h10 * KTa + h01 * Fb + h11 * KTb
        dUs = d01 * dU + d10 * Ta + d11 * Tb           # U(0) = 0, U(1) = dU
        w += g * float(F @ dUs)
    return w
