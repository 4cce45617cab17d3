"""Stability of converged states: lowest modes, critical points, branch switching, diagnosis.

A converged state is stable when the symmetric part of its tangent on the free DOFs is positive
definite; the symmetric part is the Hessian of the strain energy (exponential-map charts of the
rotations), exact for dead forces and for moments in a plane. The number of its negative
eigenvalues is read from the LDL^T factor (:mod:`homtex.analysis.tangent`). Lowest modes come from
shift-invert Lanczos (``scipy.sparse.linalg.eigsh``, sigma = 0) on the diagonally scaled matrix
D^-1/2 K D^-1/2 (translations and rotations made commensurate; the inertia does not change).

When a load- or displacement-controlled step lands on an unstable state (a bifurcation passed,
or the unstable branch of an imperfect one), :func:`restabilize` estimates the critical load
factor (the lowest eigenvalue interpolated to zero between the last stable and the unstable
state, refined by regula falsi on the path), perturbs the unstable state along the critical mode
both ways and descends the total potential at the same load factor (Newton with the tangent made
positive definite by a diagonal shift, Armijo line search) to the lower of the stable states.
"""

from __future__ import annotations

import logging

import numpy as np
import scipy.linalg as sla
import scipy.sparse.linalg as spla

from ..errors import SolverError
from .equilibrium import Equilibrium, StepFailed
from .tangent import one_blas_thread

log = logging.getLogger(__name__)


def lowest_modes(eq: Equilibrium, k: int = 1):
    """The k eigenvalues of the scaled free tangent nearest to zero (ascending) and their modes
    as (6n, k) increments (free DOFs; unit largest weighted entry), at the current state."""
    S = eq.sys.symmetric()
    nf = S.shape[0]
    d = np.abs(S.diagonal())
    d = np.where(d > 0, d, max(float(d.max(initial=1.0)), 1.0))
    sc = 1.0 / np.sqrt(d)
    Ss = (S.multiply(sc[:, None]).multiply(sc[None, :])).tocsc()
    k = max(1, min(k, nf - 1))
    if nf <= 400:
        with one_blas_thread():
            mu, V = sla.eigh(Ss.toarray())
        order = np.argsort(np.abs(mu))[:k]
        mu, V = mu[order], V[:, order]
    else:
        try:
            mu, V = spla.eigsh(Ss, k=k, sigma=0.0, which="LM", tol=1e-8)
        except RuntimeError:            # exactly singular: shift a little
            mu, V = spla.eigsh(Ss, k=k, sigma=-1e-8, which="LM", tol=1e-8)
    order = np.argsort(mu)
    mu, V = mu[order], V[:, order] * sc[:, None]
    modes = np.zeros((6 * eq.n, len(mu)))
    modes[eq.free] = V
    for c in range(modes.shape[1]):
        modes[:, c] /= max(float(np.abs(eq.w * modes[:, c]).max()), 1e-300)
    return mu, modes


def potential(eq: Equilibrium, lam: float) -> float:
    """U - lam f . (u, log Q): the total potential of dead forces (and moments in a plane), N mm."""
    return float(eq.cor.energy.sum()) - lam * float(eq.f @ eq.cor.u().ravel())


def minimize(eq: Equilibrium, lam: float, max_iter: int = 200) -> int:
    """Descend the total potential at fixed ``lam`` to a stable equilibrium from the current state
    (not necessarily in equilibrium). Returns iterations; raises StepFailed."""
    s = eq.s
    sigma = 1e-3
    for it in range(1, max_iter + 1):
        eq.evaluate()
        r = eq.residual(lam)
        rn = float(np.linalg.norm(r))
        eq.check_iterate(rn, it)
        eq.factor(inertia=True)
        conv = eq.converged(rn, lam)
        if conv and eq.negative == 0:
            eq.fresh = True
            return it
        if eq.negative:
            base = None
            while True:
                base = eq.sys.shift_diagonal(sigma, base)
                eq.sys.factor(inertia=True)
                if eq.sys.negative == 0:
                    break
                sigma *= 10.0
                if sigma > 1e8:
                    raise StepFailed("no positive-definite shift of the tangent found")
            if conv:                    # a saddle: push along the negative mode
                eq.sys.shift_diagonal(0.0, base)
                eq.sys.factor(inertia=True)
                _, modes = lowest_modes(eq, 1)
                eq.apply(s.perturbation * eq.length * modes[eq.free, 0])
                continue
            sigma = max(sigma / 10.0, 1e-6)
        d = eq.sys.solve(r)
        # cap the step: 0.3 rad of spin and 5 % of the structure size per iteration
        du = np.zeros(6 * eq.n)
        du[eq.free] = d
        big = max(float(np.abs(du.reshape(-1, 6)[:, 3:]).max(initial=0.0)) / 0.3,
                  float(np.abs(du.reshape(-1, 6)[:, :3]).max(initial=0.0)) / (0.05 * eq.length))
        if big > 1.0:
            d = d / big
        slope = float(r @ d)            # -dPi/dalpha at 0 (> 0: descent)
        if slope <= 0.0:                # round-off in a nearly singular solve: steepest descent
            d = r * (0.01 * eq.length / max(float(np.abs(r).max()), 1e-300))
            slope = float(r @ d)
        base_state = eq.snapshot()
        U0 = float(eq.cor.energy.sum())
        alpha = 1.0
        for _ in range(30):             # Armijo backtracking on the total potential
            eq.apply(alpha * d)
            eq.evaluate()
            if eq.potential_drop(lam, d, alpha, U0) <= -1e-4 * alpha * slope:
                break
            eq.restore(base_state, refresh=False)
            alpha *= 0.5
        else:
            eq.apply(alpha * d)
    raise StepFailed(f"no stable equilibrium found at lambda = {lam:.6g} in {max_iter} descent iterations")


def restabilize(eq: Equilibrium, rec, snap_prev, control: str) -> int:
    """The current state (converged at eq.lam) is unstable. Locate the first critical point on the
    path from ``snap_prev`` (stable): bisection on the inertia until one eigenvalue only is
    negative, then regula falsi on the lowest eigenvalue; record it; perturb the state with one
    negative eigenvalue along its critical mode both ways and descend the total potential there.
    The lower stable state becomes the current one (its load factor may be below eq.lam: the
    caller goes on stepping from it). Returns the descent iterations."""
    lam0, lam1 = snap_prev[2], eq.lam
    a, b, state_b, nb = lam0, lam1, eq.snapshot(), int(eq.negative)
    for _ in range(40):
        if nb == 1 or b - a < 1e-4 * (lam1 - lam0):      # (a multiple eigenvalue never gives one)
            break
        mid = 0.5 * (a + b)
        eq.restore(snap_prev)
        try:
            eq.correct(mid)
        except StepFailed as err:
            raise SolverError(f"control={control!r}: the state at load factor {lam1:.6g} is unstable ({nb} negative "
                              f"eigenvalues) and the path back to {lam0:.6g} could not be followed to locate the "
                              f"critical point ({err.reason}); use smaller steps or control='arclength'") from None
        if eq.negative:
            b, state_b, nb = mid, eq.snapshot(), int(eq.negative)
        else:
            a = mid
            snap_prev = eq.snapshot()
    eq.restore(state_b)
    mu_b, modes = lowest_modes(eq, 2)
    phi = modes[:, 0]
    lam_c = _critical_point(eq, snap_prev, b, float(mu_b[0]))
    rec.event("bifurcation", lam_c, nb)
    log.info("%s control: unstable state at lambda = %.6g; critical point at %.6g; switching along the critical "
             "mode at %.6g", control, lam1, lam_c, b)
    best = None
    amp = eq.s.perturbation * eq.length
    for sign in (1.0, -1.0):
        eq.restore(state_b, refresh=False)
        eq.apply(sign * amp * phi[eq.free])
        try:
            its = minimize(eq, b)
        except (StepFailed, SolverError) as err:
            log.debug("branch switch (%+g) failed: %s", sign, getattr(err, "reason", err))
            continue
        pi = potential(eq, b)
        if best is None or pi < best[0] - 1e-12 * abs(pi):
            best = (pi, eq.snapshot(), its)
    if best is None:
        eq.restore(state_b)
        raise SolverError(f"control={control!r}: the state at load factor {b:.6g} is unstable (critical point at "
                          f"{lam_c:.6g}) and no stable state was found along the critical mode; follow the path with "
                          "control='arclength' or with smaller steps")
    eq.restore(best[1])
    return best[2]


def arc_bifurcation(eq: Equilibrium, rec, snap_prev, neg_prev: int) -> bool:
    """After an arc-length step whose inertia grew: if the critical mode is orthogonal to the load
    direction (a symmetric bifurcation, not a limit point), record the critical point and move to
    the lower stable state along the mode at the same load factor. Returns whether it switched."""
    if not eq.negative or neg_prev < 0 or eq.negative <= neg_prev or eq.nonconservative:
        return False
    mu, modes = lowest_modes(eq, 2)
    phi = modes[eq.free, 0]
    q = eq.load_direction()
    cos = abs(float(phi @ q)) / max(float(np.linalg.norm(phi) * np.linalg.norm(q)), 1e-300)
    if cos > 1e-3:
        return False
    here, lam = eq.snapshot(), eq.lam
    lam_c = _critical_point(eq, snap_prev, lam, float(mu[0]))
    rec.event("bifurcation", lam_c, int(neg_prev) + 1)
    best = None
    for sign in (1.0, -1.0):
        eq.restore(here, refresh=False)
        eq.apply(sign * eq.s.perturbation * eq.length * phi)
        try:
            minimize(eq, lam)
        except (StepFailed, SolverError):
            continue
        pi = potential(eq, lam)
        if best is None or pi < best[0] - 1e-12 * abs(pi):
            best = (pi, eq.snapshot())
    if best is None:
        eq.restore(here)
        return False
    log.info("arc length: bifurcation at lambda = %.6g, switched to the stable branch at %.6g", lam_c, lam)
    eq.restore(best[1])
    return True


def _critical_point(eq: Equilibrium, snap_a, lam_b: float, mu_b: float, refine: int = 2) -> float:
    """Load factor where the lowest eigenvalue crosses zero between ``snap_a`` (stable) and lam_b
    (one negative eigenvalue mu_b): regula falsi on the path (the state is left arbitrary)."""
    eq.restore(snap_a)
    lam_a = snap_a[2]
    mu_a = float(lowest_modes(eq, 1)[0][0])
    if not mu_a > 0 or not mu_b < 0:
        return lam_b
    a, fa, b, fb = lam_a, mu_a, lam_b, mu_b
    lam_c = a + (b - a) * fa / (fa - fb)
    for _ in range(refine):
        eq.restore(snap_a)
        try:
            eq.correct(lam_c)
        except StepFailed:
            break
        mu = float(lowest_modes(eq, 2)[0][0])
        if mu > 0:
            a, fa = lam_c, mu
        else:
            b, fb = lam_c, mu
        lam_c = a + (b - a) * fa / (fa - fb)
    return lam_c


def diagnose_failure(eq: Equilibrium, rec, control: str, target: float, err: StepFailed) -> SolverError:
    """The SolverError for a step that failed at every size: a limit point of the load (load
    control), a turning point of the prescribed motion (displacement control) or plain
    non-convergence, judged by the lowest eigenvalue of the tangent against its initial value."""
    lam = eq.lam
    mu = float(lowest_modes(eq, 1)[0][0])
    here = eq.snapshot()
    eq.restore(rec.initial)
    mu0 = float(lowest_modes(eq, 1)[0][0])
    eq.restore(here)
    ratio = mu / mu0 if mu0 > 0 else np.nan
    rec.event("limit", lam, 0)
    if np.isfinite(ratio) and ratio < 0.2:
        if control == "load":
            return SolverError(
                f"control='load': the load factor cannot pass {lam:.6g}: no equilibrium was found beyond it on the "
                f"stable branch (steps cut to {target - lam:.2e}), and the tangent there is nearly singular (lowest "
                f"eigenvalue {ratio:.2e} of its initial value): a limit point (maximum) of the load at about "
                f"{lam:.6g} x the loads. Past it the structure snaps; follow the path through the limit point with "
                "control='arclength' (the loads as the reference load)")
        return SolverError(
            f"control='displacement': the prescribed motion cannot pass load factor {lam:.6g}: no equilibrium "
            f"was found beyond it on this branch (steps cut to {target - lam:.2e}) and the tangent is nearly "
            f"singular (lowest eigenvalue {ratio:.2e} of its initial value): a turning point of the prescribed "
            "motion (snap-back). Follow the path through it with control='arclength' (the prescribed motion as the "
            "reference)")
    return SolverError(
        f"solve_nonlinear (control={control!r}): the step beyond load factor {lam:.6g} did not converge down to a "
        f"step of {target - lam:.2e} ({err.reason}; lowest tangent eigenvalue {ratio:.2e} of its initial value, "
        "so not a limit point); check the loads and supports, or raise max_iter")
