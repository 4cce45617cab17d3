"""Critical points met by load and displacement control: a bifurcation (switch to the stable
branch along the critical mode) or a limit point (snap to the stable branch at the same load).

A converged state is stable when the symmetric part of its tangent on the free DOFs is positive
definite (the Hessian of the strain energy in exponential-map charts; exact for dead forces and
moments in a plane); its negative eigenvalues are counted from the LDL^T factor and checked
against the lowest eigenvalues of the diagonally scaled tangent, so that a neutral mode is not
read as unstable (:meth:`~homtex.analysis.equilibrium.Equilibrium.lowest_modes`).

When a load- or displacement-controlled step lands on an unstable state, :func:`handle_unstable`
isolates the first critical point on the step (bisection on the inertia, then regula falsi on the
lowest eigenvalue), and

* at a symmetric bifurcation (critical mode orthogonal to the load direction) records it and
  follows the secondary branch from the critical state along the mode (a recorded perturbation
  of ``perturbation`` x the structure size, the mode's sign fixed) by arc length to the step's
  load factor, recording the stable states passed: the physical path of a perfect structure;
* otherwise (a limit point the corrector jumped over) snaps like :func:`snap_through`.

When a step cannot be completed at any size next to a nearly singular tangent (a limit point of
the load, or a turning point of a prescribed motion), :func:`snap_through` follows the path by arc
length through the unstable branch until it comes back, stable, to the load factor of the last
stable state, and records the jump there: the structure snaps at (practically) fixed load, and
the energy it releases is recorded as stabilisation energy (the path is then flagged).
"""

from __future__ import annotations

import copy
import logging

import numpy as np

from ..errors import SolverError
from .continuation import _multiple, continue_to, critical_point, mode_along
from .equilibrium import Equilibrium, StepFailed

log = logging.getLogger(__name__)

#: a critical mode whose cosine with the load direction is below this is a symmetric bifurcation
ORTHOGONAL = 1e-3


def handle_unstable(eq: Equilibrium, rec, snap_prev, control: str) -> None:
    """The current state (converged at eq.lam, the end of a step from the stable ``snap_prev``) is
    unstable: locate the first critical point, record it and reach a stable state at eq.lam (see
    the module docstring); the states passed are recorded."""
    lam0, lam1 = snap_prev[2], eq.lam
    target = lam1
    a, b, state_b, nb = lam0, lam1, eq.snapshot(), int(eq.negative)
    for _ in range(60):
        # one critical point in [a, b]: a single negative eigenvalue, or a multiple one (the two
        # bending planes of a round rod), close enough for the regula falsi
        if (nb == 1 or _multiple(eq, nb)) and b - a <= 0.05 * max(b - lam0, 1e-300) or b - a < 1e-12:
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
    mu_b, modes = eq.lowest_modes(2)
    phi = modes[:, 0]
    q = eq.load_direction()
    cos = abs(float(phi[eq.free] @ q)) / max(float(np.linalg.norm(phi[eq.free]) * np.linalg.norm(q)), 1e-300)
    lam_c = critical_point(eq, snap_prev, b, float(mu_b[0]))
    if cos > ORTHOGONAL:
        log.info("%s control: unstable state at %.6g past a limit point near %.6g: snapping", control, lam1, lam_c)
        eq.restore(snap_prev)
        rec.record(eq, 0, float(np.linalg.norm(eq.residual(eq.lam))))
        snap_through(eq, rec, control, target)
        return
    rec.event("bifurcation", lam_c, nb)
    # the critical state on the primary path, then the secondary branch along the mode
    eq.restore(snap_prev)
    try:
        eq.correct(lam_c)
        if eq.negative:
            raise StepFailed("past the critical point")
    except StepFailed:
        eq.restore(snap_prev)
    rec.record(eq, 0, float(np.linalg.norm(eq.residual(eq.lam))))
    mode = mode_along(eq, phi)
    rec.along(eq, mode)             # the path leaves the critical state along the mode
    amp = eq.s.perturbation * eq.length
    rec.event("switch", eq.lam, nb)
    rec.switches.append((float(eq.lam), amp))
    log.info("%s control: bifurcation at %.6g (%d negative eigenvalue(s)); following the secondary branch along "
             "the critical mode (perturbation %.3g mm) to %.6g", control, lam_c, nb, amp, target)
    if eq.lam >= target:
        return
    try:
        continue_to(eq, rec, target, amp, mode=mode, record=True)
    except SolverError as err:
        raise SolverError(f"control={control!r}: bifurcation at load factor {lam_c:.6g}: the secondary branch along "
                          f"the critical mode could not be followed to {target:.6g} ({err}); follow the path with "
                          "control='arclength'") from None


def snap_through(eq: Equilibrium, rec, control: str, lam_try: float) -> None:
    """From the current stable state (the last one before a limit or turning point; no equilibrium
    was found near it at ``lam_try``, a little further) the structure snaps: it leaves along the
    critical mode, oriented as the path was moving (a recorded perturbation), and its total
    potential is descended at ``lam_try`` to the stable state it falls into (:func:`descend`;
    overdamped dynamics). Where the descent finds no other stable state, the path is followed by arc
    length through the unstable branch until it returns, stable, to the current load factor. The
    jump is recorded with the energy it released."""
    start, lam_s = eq.snapshot(), eq.lam
    travel = eq.tangent_vector()            # du / dlambda: towards the limit, nearly along the mode
    _, modes = eq.lowest_modes(1)
    phi = modes[:, 0]
    if float((eq.w * phi) @ (eq.w * travel)) < 0.0:
        phi = -phi
    amp = eq.s.perturbation * eq.length
    reasons = []
    for lam, a in ((lam_try, amp), (lam_try, 4 * amp), (lam_s, 16 * amp)):
        try:
            eq.apply(np.zeros(len(eq.free)), lam - lam_s)       # the prescribed motions at lam too
            eq.lam = lam
            descend(eq, lam, phi, a)
            if eq.norm(eq.increment_since(start)) < a:
                raise StepFailed("the descent fell back into the state it started from")
            how = f"descent along the critical mode (perturbation {a:.3g} mm)"
            amp = a
            break
        except (StepFailed, SolverError) as err:
            reasons.append(getattr(err, "reason", str(err)))
            eq.restore(start)
    else:
        if _knee(eq, rec, lam_try):
            return
        try:
            ds = max(eq.norm(eq.tangent_vector()) * 1e-3, 1e-6 * eq.length)
            continue_to(eq, rec, lam_s, ds, after_turn=True)
            how = "arc length through the unstable branch"
        except SolverError as err2:
            eq.restore(start)
            what = ("limit point (maximum) of the load" if control == "load" else
                    "turning point of the prescribed motion")
            raise SolverError(f"control={control!r}: the load factor cannot pass {lam_s:.6g}: a {what} there; no "
                              f"stable state to snap to was found (descent: {reasons[-1]}; path: {err2}); follow it "
                              "with control='arclength'") from None
    rec.event("snap", eq.lam, 0)
    rec.switches.append((float(eq.lam), float(amp)))
    rec.record(eq, 0, float(np.linalg.norm(eq.residual(eq.lam))), start, jump=True)
    log.info("%s control: snapped at load factor %.6g to a stable state by %s (released %.3g N mm)", control, eq.lam,
             how, rec.rows[-1]["stabilization_energy"])


def descend(eq: Equilibrium, lam: float, direction: np.ndarray, amp: float, max_iter: int = 400,
            max_escapes: int = 6) -> int:
    """Perturb the state by ``amp`` x ``direction`` (6n,) and descend the total potential
    Pi = U - lam f . u at fixed load factor to a stable equilibrium: Newton on K + M / delta (M the
    tangent's |diagonal|, frozen; delta grows after full steps and shrinks when the factor is
    indefinite or the line search cuts: pseudo-transient continuation), steps capped at 0.3 rad
    and 5 % of the structure size, Armijo on Pi. An equilibrium with a negative eigenvalue (a
    saddle: Newton converges to those too) is left along its negative mode, oriented along
    ``direction``; one that the escape leads back to at the same potential is neutral, not a
    saddle, and is accepted. Returns the iterations; StepFailed."""
    eq.apply(amp * direction[eq.free])
    eq.evaluate()
    eq.factor()
    M = np.maximum(np.abs(eq.sys.diagonal()), 1e-12 * float(np.abs(eq.sys.diagonal()).max(initial=1.0)))
    delta, r_prev = 1.0, None
    escapes, saddle = 0, None
    for it in range(1, max_iter + 1):
        eq.evaluate()
        r = eq.residual(lam)
        rn = float(np.linalg.norm(r))
        eq.check_iterate(rn, it)
        if eq.converged(rn, lam):
            eq.factor(inertia=True)
            pi = float(eq.cor.energy.sum()) - lam * float(eq.f @ eq.cor.u().ravel())
            if saddle is not None and pi > saddle[1] - 1e-10 * abs(saddle[1]):
                eq.restore(saddle[0])          # the escape found nothing lower: a neutral direction
                return it
            if not eq.sys.negative:
                eq.fresh = True
                return it
            escapes += 1
            if escapes > max_escapes:
                raise StepFailed(f"the descent kept meeting saddles at load factor {lam:.6g}")
            _, modes = eq.lowest_modes(1)
            phi = modes[:, 0]
            if float((eq.w * phi) @ (eq.w * direction)) < 0.0:
                phi = -phi
            saddle = (eq.snapshot(), pi)
            eq.apply(amp * phi[eq.free])
            delta, r_prev = 1.0, None
            continue
        eq.factor()
        base = eq.sys.A.data.copy()
        for _ in range(60):
            eq.sys.A.data[:] = base
            eq.sys.add_diagonal(M / delta)
            eq.sys.factor(inertia=True)
            if eq.sys.negative == 0:
                break
            delta /= 4.0
        else:
            raise StepFailed("no positive-definite pseudo-transient shift of the tangent")
        d = eq.sys.solve(r)
        du = np.zeros(6 * eq.n)
        du[eq.free] = d
        big = max(float(np.abs(du.reshape(-1, 6)[:, 3:]).max(initial=0.0)) / 0.3,
                  float(np.abs(du.reshape(-1, 6)[:, :3]).max(initial=0.0)) / (0.05 * eq.length))
        if big > 1.0:
            d = d / big
        slope = float(r @ d)
        snap, U0 = eq.snapshot(), float(eq.cor.energy.sum())
        alpha = 1.0
        for _ in range(30):
            eq.apply(alpha * d)
            eq.evaluate()
            if eq.potential_drop(lam, d, alpha, U0) <= -1e-4 * alpha * slope:
                break
            eq.restore(snap, refresh=False)
            alpha *= 0.5
        else:
            eq.apply(alpha * d)
        if alpha < 1.0:
            delta /= 4.0
        else:                           # a full step: towards Newton (faster as the residual falls)
            ratio = 1.0 if r_prev is None else r_prev / max(rn, 1e-300)
            delta = min(delta * float(np.clip(ratio, 2.0, 10.0)), 1e12)
        r_prev = rn
    raise StepFailed(f"no stable equilibrium reached at load factor {lam:.6g} in {max_iter} descent iterations")


def _knee(eq: Equilibrium, rec, lam_try: float) -> bool:
    """No stable state to snap to at ``lam_try``: the nearly singular tangent may be a sharp knee
    of a stable path (an imperfect column close to its bifurcation load), not a limit point. Follow
    the path by arc length to ``lam_try``, recording its stable states; True when it gets there
    without the load factor turning back (else the state is restored and False returned)."""
    start, saved = eq.snapshot(), copy.deepcopy(rec.__dict__)     # the recorder's ledger too
    n_events = len(rec.events)
    try:
        ds = max(eq.norm(eq.tangent_vector()) * 1e-3, 1e-6 * eq.length)
        continue_to(eq, rec, lam_try, ds, record=True)
    except (StepFailed, SolverError):
        pass
    else:
        if all(k not in ("limit", "bifurcation") for k, _, _ in rec.events[n_events:]):
            log.info("load factor %.6g: a sharp knee of a stable path, followed by arc length", lam_try)
            return True
    rec.__dict__.clear()
    rec.__dict__.update(saved)
    eq.restore(start)
    return False


def is_limit(eq: Equilibrium, rec) -> tuple[bool, float]:
    """(whether the current state is next to a limit or turning point, the lowest eigenvalue over
    the initial one): the tangent is nearly singular, its lowest eigenvalue below 0.2 of the start's."""
    mu = float(eq.lowest_modes(1)[0][0])
    here = eq.snapshot()
    eq.restore(rec.initial)
    mu0 = float(eq.lowest_modes(1)[0][0])
    eq.restore(here)
    ratio = mu / mu0 if mu0 > 0 else np.nan
    return bool(np.isfinite(ratio) and ratio < 0.2), ratio


def not_converged(eq: Equilibrium, control: str, target: float, err: StepFailed, ratio: float) -> SolverError:
    """The SolverError of a step that failed at every size away from any critical point."""
    return SolverError(
        f"solve_nonlinear (control={control!r}): the step beyond load factor {eq.lam:.6g} did not converge down to a "
        f"step of {target - eq.lam:.2e} ({err.reason}; lowest tangent eigenvalue {ratio:.2e} of its initial value, "
        "so not a limit point); check the loads and supports, or raise max_iter")
