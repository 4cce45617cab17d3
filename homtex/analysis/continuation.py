"""Arc-length steps that cannot step over a critical point, and continuation to a load factor.

An arc step (Crisfield's cylindrical arc length: |du|_W = ds, rotations weighted by the structure
size) is accepted only when the path inside it is resolved:

* the corrector stays within ``DEVIATION`` ds of the tangent predictor (the path turns by less
  than about 30 degrees in the step);
* the work of the step (:func:`~homtex.analysis.energy.hermite_work`) matches its strain-energy
  change within ``ENERGY_TOL`` (a step that spans an unstable branch or jumps to another branch
  does not: its end states are equilibria, the path between them is not the one interpolated);
* it contains at most one critical point: the number of negative eigenvalues changes by at most
  one (two at once only for a multiple eigenvalue, e.g. the two bending planes of a round rod),
  and the load factor turns back (a limit point) only together with a change of stability;
* no element ends beyond ``MAX_STRAIN`` (a corrector that converged on a nonphysical branch).

A rejected step is halved. A limit point inside an accepted step is located from the load factor
and its slope at both ends (cubic Hermite: fourth order); a bifurcation from the lowest
eigenvalue (regula falsi on the path). :func:`continue_to` follows the path from a state, along
the tangent or along a critical mode (branch switching), until a stable state at a given load
factor is reached: how load and displacement control pass bifurcations and snap past limit points.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from ..errors import SolverError
from .equilibrium import Equilibrium, StepFailed

log = logging.getLogger(__name__)

#: largest |increment - predictor|_W / ds of an accepted arc step
DEVIATION = 0.5
#: largest relative mismatch of a step's work and strain-energy change
ENERGY_TOL = 0.01
#: an accepted state has no element beyond this axial strain (the element is small-strain; a
#: corrector that lands there has jumped to a nonphysical branch)
MAX_STRAIN = 0.5


@dataclass
class Arc:
    """An accepted arc step: Newton iterations, residual, load-factor change, the (6n,) increment,
    the slopes dlambda/ds at its start and end, the tangent at its end and the inertia there."""

    iterations: int
    residual: float
    dlam: float
    inc: np.ndarray
    slope0: float
    slope1: float
    tangent: np.ndarray
    negative: int


def oriented_slope(eq: Equilibrium, t: np.ndarray, along: np.ndarray | None) -> float:
    """dlambda/ds at a state with tangent t (du / dlambda), the path oriented along ``along``
    (an increment; None: increasing lambda)."""
    nt = eq.norm(t)
    if nt == 0.0:
        return np.inf
    if along is None:
        return 1.0 / nt
    return (1.0 if float((eq.w * t) @ (eq.w * along)) >= 0.0 else -1.0) / nt


def arc_step(eq: Equilibrium, ds: float, t0: np.ndarray, prev, predictor=None):
    """Newton on the arc of radius ds about the current (converged, fresh) state. The predictor is
    the tangent t0 (oriented along ``prev``) or ``predictor`` = ((6n,) increment, dlambda).
    Returns (iterations, residual, dlambda, increment, predicted increment); StepFailed."""
    s = eq.s
    lam0 = eq.lam
    if predictor is None:
        slope = oriented_slope(eq, t0, prev)
        dlam = slope * ds
        pred = dlam * t0
    else:
        pred, dlam = predictor
    inc = eq.apply(pred[eq.free], dlam)
    eq.lam = lam0 + dlam
    it = 1
    while True:
        try:
            eq.evaluate()
        except SolverError as err:
            raise StepFailed(str(err)) from None
        r = eq.residual(eq.lam)
        rn = float(np.linalg.norm(r))
        eq.check_iterate(rn, it)
        if eq.converged(rn, eq.lam):
            break
        if it >= s.max_iter:
            raise StepFailed(f"did not converge in {s.max_iter} iterations (out-of-balance {rn:.3e})", rn)
        eq.factor()
        dI = eq.sys.solve(r)
        tII = eq.ubar.ravel().copy()
        tII[eq.free] = eq.sys.solve(eq.load_direction())
        vI = np.zeros_like(inc)
        vI[eq.free] = dI
        wa, wb, wt = eq.w * (inc + vI), eq.w * tII, eq.w * inc
        a = float(wb @ wb)
        b = 2.0 * float(wa @ wb)
        c = float(wa @ wa) - ds * ds
        disc = b * b - 4.0 * a * c
        if disc < 0.0:
            raise StepFailed("the arc-length constraint has no real root (step too large)", rn)
        sq = np.sqrt(disc)
        roots = ((-b + sq) / (2 * a), (-b - sq) / (2 * a))
        dl = max(roots, key=lambda x: float((wa + x * wb) @ wt))        # the root that turns least
        d = vI + dl * tII
        eq.apply(d[eq.free], dl)
        eq.lam += dl
        inc = inc + d
        it += 1
    eq.factor(inertia=s.stability)
    eq.fresh = True
    return it, rn, eq.lam - lam0, inc, pred


def checked_arc_step(eq: Equilibrium, rec, ds: float, t0: np.ndarray, prev, neg0: int, predictor=None) -> Arc:
    """An arc step with the acceptance checks of the module docstring (StepFailed when one fails;
    the caller restores the state)."""
    slope0 = oriented_slope(eq, t0, prev) if predictor is None else 0.0
    start = rec.ends(eq, t0 if predictor is None else predictor[0])
    it, rn, dlam, inc, pred = arc_step(eq, ds, t0, prev, predictor)
    if predictor is None:
        dev = eq.norm(inc - pred)
        if dev > DEVIATION * ds:
            raise StepFailed(f"the path turned by {dev / ds:.2f} of the arc inside the step (halved to resolve it)")
    axial = np.abs(eq.cor.forces[:, 6] / eq.cor.arrays[0]).max(initial=0.0)
    if axial > MAX_STRAIN:
        raise StepFailed(f"the corrector landed at an axial strain of {axial:.3g} (a nonphysical branch)")
    t1 = eq.tangent_vector()
    err = rec.step_energy_error(eq, start, rec.ends(eq, t1))
    if err > ENERGY_TOL:
        raise StepFailed(f"the step's work misses its strain energy by {100 * err:.3g} % (it spans a jump or an "
                         "unstable branch)")
    slope1 = oriented_slope(eq, t1, inc)
    neg1 = -1 if eq.negative is None else int(eq.negative)
    if neg0 >= 0 and neg1 >= 0 and predictor is None:
        turned = np.sign(slope0) != np.sign(slope1)
        dneg = abs(neg1 - neg0)
        if dneg > 1 and not _multiple(eq, dneg):
            raise StepFailed(f"the stability changed by {dneg} eigenvalues inside one step")
        if turned and dneg == 0:
            raise StepFailed("the load factor turned back without a change of stability (two critical points)")
    return Arc(it, rn, dlam, inc, slope0, slope1, t1, neg1)


def _multiple(eq: Equilibrium, k: int) -> bool:
    """True when the k lowest eigenvalues of the scaled tangent nearly coincide (a multiple one)."""
    mu, _ = eq.lowest_modes(k + 1)
    low = mu[np.argsort(np.abs(mu))[:k]]       # the k nearest zero: those that crossed it
    return bool(np.ptp(low) <= 1e-3 * max(float(np.abs(low).max()), 1e-300))


def limit_on_step(lam0: float, lam1: float, ds: float, slope0: float, slope1: float) -> float:
    """Extremum of the load factor inside a step from its values and slopes dlambda/ds at both ends
    (cubic Hermite in the arc length)."""
    return _hermite_extremum(lam0, lam1, ds, slope0, slope1)[0]


def _hermite_extremum(lam0, lam1, ds, slope0, slope1) -> tuple[float, float]:
    """(extremal load factor, its position in [0, 1]) of the cubic Hermite lambda(s) of a step."""
    m0, m1 = slope0 * ds, slope1 * ds
    a = 3 * (2 * lam0 + m0 - 2 * lam1 + m1)
    b = 2 * (-3 * lam0 - 2 * m0 + 3 * lam1 - m1)
    c = m0
    roots = np.roots([a, b, c]) if abs(a) > 1e-300 else (np.array([-c / b]) if b != 0 else np.array([]))
    roots = [float(r.real) for r in np.atleast_1d(roots) if abs(r.imag) < 1e-12 and 0.0 <= r.real <= 1.0]
    if not roots:
        return (lam1, 1.0) if abs(lam1) > abs(lam0) else (lam0, 0.0)
    s = roots[0]
    lam = ((2 * s ** 3 - 3 * s ** 2 + 1) * lam0 + (s ** 3 - 2 * s ** 2 + s) * m0 + (-2 * s ** 3 + 3 * s ** 2) * lam1 +
           (s ** 3 - s ** 2) * m1)
    return float(lam), s


def locate_limit(eq: Equilibrium, snap, t0: np.ndarray, prev, ds: float, arc: Arc, iterations: int = 4) -> float:
    """The load factor at the limit point inside the accepted step ``arc`` from ``snap`` (radius ds,
    start tangent t0 oriented along ``prev``): the Hermite estimate refined by arc steps from the
    start to the estimated position, keeping the sub-step where dlambda/ds changes sign (the
    state is left at the end of ``arc``)."""
    end = eq.snapshot()
    lo, hi = 0.0, ds
    la, sa, lb, sb = snap[2], arc.slope0, end[2], arc.slope1
    lam_c, pos = _hermite_extremum(la, lb, hi - lo, sa, sb)
    for _ in range(iterations):
        s_mid = lo + min(max(pos, 0.1), 0.9) * (hi - lo)
        eq.restore(snap)
        try:
            _, _, _, inc, _ = arc_step(eq, s_mid, t0, prev)
        except StepFailed:
            break
        lam_m, slope_m = eq.lam, oriented_slope(eq, eq.tangent_vector(), inc)
        if np.sign(slope_m) == np.sign(sa):
            lo, la, sa = s_mid, lam_m, slope_m
        else:
            hi, lb, sb = s_mid, lam_m, slope_m
        lam_c, pos = _hermite_extremum(la, lb, hi - lo, sa, sb)
    eq.restore(end)
    return lam_c


def critical_point(eq: Equilibrium, snap_a, lam_b: float, mu_b: float, refine: int = 3) -> float:
    """Load factor where the lowest eigenvalue crosses zero between ``snap_a`` (stable, lambda_a)
    and lambda_b (eigenvalue mu_b < 0): regula falsi on the path at fixed load factors (the state
    is left arbitrary)."""
    eq.restore(snap_a)
    lam_a = snap_a[2]
    mu_a = float(eq.lowest_modes(1)[0][0])
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
        mu = float(eq.lowest_modes(1)[0][0])
        if mu > 0:
            a, fa = lam_c, mu
        else:
            b, fb = lam_c, mu
        lam_c = a + (b - a) * fa / (fa - fb)
    return lam_c


def mode_along(eq: Equilibrium, phi: np.ndarray) -> np.ndarray:
    """The critical mode with a fixed sign (its largest weighted entry positive) and unit weighted
    norm: the recorded direction of a branch switch."""
    k = int(np.argmax(np.abs(eq.w * phi)))
    phi = phi if phi[k] >= 0 else -phi
    return phi / max(eq.norm(phi), 1e-300)


def continue_to(eq: Equilibrium, rec, target: float, ds: float, *, mode: np.ndarray | None = None,
                record: bool = False, after_turn: bool = False, budget: int = 400, max_cuts: int = 12) -> int:
    """Follow the path from the current (converged, fresh) state until a stable state at load
    factor ``target`` (the first stable crossing of ``target`` from below; ``after_turn``: only
    after the load factor has turned back once, i.e. past a limit point) and land on it exactly.
    The first step goes along ``mode`` (a critical mode: branch switching; the arc radius ds is its
    amplitude) or along the tangent. ``record``: record every stable state passed (a stable
    secondary branch); else only limit points are noted (the first one). Returns the arc steps
    taken; SolverError when no stable crossing is found within ``budget`` steps."""
    ds0 = ds
    prev = None
    neg = -1 if eq.negative is None else int(eq.negative)
    t = eq.tangent_vector()
    taken = turns = cuts = 0
    predictor = None if mode is None else (ds * mode, 0.0)
    while taken < budget:
        snap = eq.snapshot()
        try:
            arc = checked_arc_step(eq, rec, ds, t, prev, neg, predictor)
        except StepFailed as err:
            eq.restore(snap)
            ds *= 0.5
            cuts += 1
            if predictor is not None:
                predictor = (ds * mode, 0.0)
            if cuts > max_cuts:
                raise SolverError(f"continuation from load factor {snap[2]:.6g} stalled ({err.reason})") from None
            continue
        if predictor is None and np.sign(arc.slope0) != np.sign(arc.slope1):
            turns += 1
            if turns == 1 or record:
                rec.event("limit", limit_on_step(snap[2], eq.lam, ds, arc.slope0, arc.slope1), arc.negative)
        predictor = None
        taken += 1
        cuts = 0                    # max_cuts bounds the halvings in a row, not over the whole path
        stable = arc.negative == 0
        crossed = snap[2] < target <= eq.lam and (turns > 0 or not after_turn)
        if crossed and stable and land(eq, rec, snap, target):
            return taken
        if record and stable:
            rec.record(eq, arc.iterations, arc.residual, snap, arc=True)
        prev, t, neg = arc.inc, arc.tangent, arc.negative
        ds = min(2.0 * ds, 16.0 * ds0) if arc.iterations <= eq.s.desired_iterations else ds
    raise SolverError(f"no stable state at load factor {target:.6g} was reached in {budget} arc-length steps")


def land(eq: Equilibrium, rec, snap, target: float) -> bool:
    """Correct onto load factor ``target`` from the nearer of the current state and ``snap``
    (Newton at fixed load factor); True when a stable state was found there (left current)."""
    after = eq.snapshot()
    for start in ((after, snap) if abs(eq.lam - target) <= abs(target - snap[2]) else (snap, after)):
        eq.restore(start)
        try:
            eq.correct(target)
        except StepFailed:
            continue
        if not eq.negative:
            return True
    eq.restore(after)
    return False
