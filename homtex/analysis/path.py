"""Path following: load, displacement (and rotation) control and arc-length control.

All three move the load factor lambda that scales the loads and the prescribed motions (see
:mod:`homtex.analysis.equilibrium`); they differ in what is prescribed in a step:

* ``"load"`` / ``"displacement"``: lambda. The requested ``steps`` are cut in halves where a step
  fails (Newton does not converge, an element turns too far, or the corrector lands further from
  the tangent predictor than the predicted step itself: a jump to another branch); they grow
  back after easy steps; a step whose displacement per unit load factor grows more than
  ``max_growth`` (5) times over the previous step's is cut too (the path turns ahead). Every
  converged state's inertia is checked: an unstable state is never
  accepted (:func:`homtex.analysis.stability.restabilize` locates the critical point and takes the
  stable branch along the critical mode). A step that cannot be completed at any size ends in a
  :class:`~homtex.errors.SolverError` that names the limit point (or the turning point of the
  prescribed motion) and the remedy, control="arclength".
* ``"arclength"``: Crisfield's cylindrical arc length (|du|_W = ds, rotations weighted by the
  structure size) with the root of the smallest turn, the predictor direction kept by the sign of
  its product with the previous increment (through limit points), ds adapted to the Newton
  iterations (``desired_iterations``). It stops on the first crossing of lambda = 1 (the last
  state is corrected onto lambda = 1 exactly) or when ``steps`` increments are spent. A step whose
  inertia grows while its critical mode is orthogonal to the load (a symmetric bifurcation, not a
  limit point) is moved to the stable branch along the mode
  (:func:`homtex.analysis.stability.arc_bifurcation`).
"""

from __future__ import annotations

import logging

import numpy as np

from ..errors import SolverError
from .equilibrium import Equilibrium, StepFailed
from .records import PathRecorder
from .stability import arc_bifurcation, diagnose_failure, restabilize

log = logging.getLogger(__name__)


def follow_lambda(eq: Equilibrium, rec: PathRecorder, steps: int, control: str) -> None:
    """Load or displacement control from lambda = 0 to 1 in ``steps`` steps (cut where needed)."""
    s = eq.s
    h_max = 1.0 / steps
    h = h_max
    h_min = h_max / 2.0 ** s.max_cuts
    eq.refresh()
    rec.start(eq)
    k = 1                                   # next requested step
    last_error = None
    rate = None                             # |du| / dlambda of the last accepted step
    while eq.lam < 1.0 - 1e-12:
        target = min(k / steps, eq.lam + h)
        if k / steps - target < 1e-9 * h_max:
            target = k / steps
        snap = eq.snapshot()
        try:
            cap = None if rate is None else s.max_growth * rate * (target - snap[2])
            it, rn, pred = eq.correct(target, cap)
            _check_jump(eq, snap, pred)
            rate = _check_growth(eq, snap, rate, target - snap[2])
        except StepFailed as err:
            last_error = err
            eq.restore(snap)
            h = 0.5 * (target - snap[2])
            rec.cuts += 1
            log.debug("step to lambda %.6g failed (%s); cut to %.3g", target, err.reason, h)
            if h < h_min:
                raise diagnose_failure(eq, rec, control, target, last_error) from None
            continue
        switched = False
        if s.stability and eq.negative:
            it = restabilize(eq, rec, snap, control)
            rn = float(np.linalg.norm(eq.residual(eq.lam)))
            switched = True
            rate = None
        rec.record(eq, it, rn, snap)
        if not switched and it <= s.desired_iterations + 1:
            h = min(h_max, 2.0 * h)
        if abs(eq.lam - k / steps) < 1e-12:
            k += 1


def _check_jump(eq: Equilibrium, snap, pred: np.ndarray) -> None:
    """StepFailed when the corrector moved further from the tangent predictor than the predicted
    step itself (a jump to a distant branch: past a limit or turning point)."""
    d = eq.increment_since(snap)
    size = eq.norm(pred)
    dev = eq.norm(d - pred)
    if dev > eq.s.max_correction * size + 1e-12 * eq.length:
        raise StepFailed(f"the corrector moved {dev:.3g} from the predicted step of size {size:.3g} "
                         "(jump to another branch)")


def _check_growth(eq: Equilibrium, snap, rate, dlam: float):
    """StepFailed when the step's displacement per unit load factor grew more than
    ``max_growth`` times over the last accepted step's: the path turns (a limit or turning point
    ahead) or the corrector jumped to another branch; otherwise the new rate."""
    new = eq.norm(eq.increment_since(snap)) / max(abs(dlam), 1e-300)
    if rate is not None and new > eq.s.max_growth * rate + 1e-12 * eq.length / max(abs(dlam), 1e-300):
        raise StepFailed(f"the displacement per load step grew {new / rate:.3g} times (path turning or a jump)")
    return new


def follow_arclength(eq: Equilibrium, rec: PathRecorder, steps: int, arc_length: float | None) -> None:
    """Arc-length control until lambda reaches 1 or ``steps`` increments are spent."""
    s = eq.s
    eq.refresh()
    rec.start(eq)
    q = eq.load_direction()
    t = _tangent_vector(eq, eq.sys.solve(q))
    nt = eq.norm(t)
    if nt == 0.0:
        raise SolverError("control='arclength' needs a reference load or a prescribed motion that moves the frame")
    ds0 = nt / steps if arc_length is None else float(arc_length)
    ds = ds0
    ds_min = ds0 / 2.0 ** s.max_cuts
    # largest arc: 1000 first arcs, or every node moving by 5 % of the structure size
    ds_max = max(1e3 * ds0, 0.05 * eq.length * np.sqrt(eq.n))
    prev = None                              # previous converged increment (6n,)
    neg_prev = -1 if eq.negative is None else int(eq.negative)
    done = 0
    while done < steps:
        snap = eq.snapshot()
        try:
            it, rn, dlam, inc = _arc_step(eq, ds, prev)
        except StepFailed as err:
            eq.restore(snap)
            ds *= 0.5
            rec.cuts += 1
            log.debug("arc-length step ds = %.3g failed (%s)", 2 * ds, err.reason)
            if ds < ds_min:
                raise SolverError(f"control='arclength': no converged step at lambda = {snap[2]:.6g} down to an arc "
                                  f"length of {ds:.3g} ({err.reason})") from None
            continue
        if s.stability and arc_bifurcation(eq, rec, snap, neg_prev):
            inc = eq.increment_since(snap)          # the switch: the next predictor keeps its sense
            ds = max(ds, eq.norm(inc))              # and the secondary branch sets the scale
        if snap[2] < 1.0 <= eq.lam:
            _land_on_one(eq, rec, snap, it)
            return
        rec.record(eq, it, rn, snap, arc=True)
        neg_prev = -1 if eq.negative is None else int(eq.negative)
        done += 1
        prev = inc
        ds = min(ds * float(np.clip(np.sqrt(s.desired_iterations / max(it, 1)), 0.5, 2.0)), ds_max)
    rec.spent(eq)


def _tangent_vector(eq: Equilibrium, du_free: np.ndarray) -> np.ndarray:
    """(6n,) increment per unit load factor: du on the free DOFs, u_bar on the prescribed ones."""
    t = eq.ubar.ravel().copy()
    t[eq.free] = du_free
    return t


def _arc_step(eq: Equilibrium, ds: float, prev):
    """One arc-length increment of radius ``ds`` from the converged state; returns (iterations,
    residual, delta lambda, (6n,) increment)."""
    s = eq.s
    if not eq.fresh:
        eq.refresh()
    t = _tangent_vector(eq, eq.sys.solve(eq.load_direction()))
    nt = eq.norm(t)
    sign = 1.0
    if prev is not None:
        sign = 1.0 if float((eq.w * t) @ (eq.w * prev)) >= 0.0 else -1.0
    dlam = sign * ds / nt
    lam0 = eq.lam
    inc = eq.apply(dlam * t[eq.free], dlam)
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
        tII = _tangent_vector(eq, eq.sys.solve(eq.load_direction()))
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
        # the root whose new increment turns least from the current one
        dl = max(roots, key=lambda x: float((wa + x * wb) @ wt))
        d = vI + dl * tII
        eq.apply(d[eq.free], dl)
        eq.lam += dl
        inc = inc + d
        it += 1
    eq.factor(inertia=s.stability)
    eq.fresh = True
    return it, rn, eq.lam - lam0, inc


def _land_on_one(eq: Equilibrium, rec: PathRecorder, snap, it_arc: int) -> None:
    """The arc step crossed lambda = 1: correct onto lambda = 1 exactly (Newton at fixed lambda from
    the nearer of the two states) and record that state as the last one."""
    after = eq.snapshot()
    for start in ((after, snap) if eq.lam - 1.0 <= 1.0 - snap[2] else (snap, after)):
        eq.restore(start)
        try:
            it, rn, pred = eq.correct(1.0)
            _check_jump(eq, start, pred)
        except StepFailed:
            continue
        rec.record(eq, it_arc + it, rn, snap, arc=True)
        return
    eq.restore(after)
    raise SolverError(f"control='arclength': the step from lambda = {snap[2]:.6g} to {after[2]:.6g} crosses 1 but "
                      "no equilibrium at lambda = 1 was found from either end")
