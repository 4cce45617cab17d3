"""Path following: load, displacement (and rotation) control and arc-length control.

All three move the load factor lambda that scales the loads and the prescribed motions (see
:mod:`homtex.analysis.equilibrium`); they differ in what is prescribed in a step:

* ``"load"`` / ``"displacement"``: lambda. The requested ``steps`` are cut in halves where a step
  fails (Newton does not converge, an element turns too far, the corrector lands further from
  the tangent predictor than the predicted step itself, the displacement per unit load grows
  more than ``max_growth`` (5) times over the previous step's, or the step's work misses its
  strain energy: it spans a jump); they grow back after easy steps. Every converged state's
  inertia is checked: an unstable state is never accepted. At a bifurcation the secondary branch
  is followed along the critical mode; at a limit point of the load (or a turning point of the
  prescribed motion) the state snaps to the stable branch at the same load factor and the energy
  released is recorded (:mod:`homtex.analysis.stability`); the path is then flagged.
* ``"arclength"``: Crisfield's cylindrical arc length with the acceptance checks of
  :mod:`homtex.analysis.continuation` (no step spans more than one critical point or an unstable
  branch; the arc adapts to the Newton iterations). Limit points are located inside their step
  and recorded; at a symmetric bifurcation (critical mode orthogonal to the load) the path
  switches to the secondary branch along the mode. It stops on the first crossing of lambda = 1
  (the last state is corrected onto lambda = 1 exactly) or when ``steps`` increments are spent.
"""

from __future__ import annotations

import logging

import numpy as np

from ..errors import SolverError
from .continuation import ENERGY_TOL, checked_arc_step, critical_point, land, locate_limit, mode_along
from .equilibrium import Equilibrium, StepFailed
from .records import PathRecorder
from .stability import ORTHOGONAL, descend, handle_unstable, is_limit, not_converged, snap_through

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
            new_rate = _check_growth(eq, snap, rate, target - snap[2])
            if not eq.negative:
                err = rec.step_energy_error(eq, rec.prev, rec.ends(eq))
                if err > ENERGY_TOL:
                    raise StepFailed(f"the step's work misses its strain energy by {100 * err:.3g} % (a jump)")
            # only an accepted step sets the rate: a rejected one (a stiffening structure's first
            # long step, whose work misses its energy) would cap every shorter retry below its own
            # linear predictor, and the step would be cut to nothing
            rate = new_rate
        except StepFailed as err:
            eq.restore(snap)
            h = 0.5 * (target - snap[2])
            rec.cuts += 1
            log.debug("step to lambda %.6g failed (%s); cut to %.3g", target, err.reason, h)
            if h < h_min:
                limit, ratio = is_limit(eq, rec)
                if limit:
                    snap_through(eq, rec, control, target)
                    h, rate = h_max, None
                elif _settle(eq, rec, snap, target):
                    h, rate = 2.0 * (target - snap[2]), None
                    if abs(eq.lam - k / steps) < 1e-12:
                        k += 1
                else:
                    raise not_converged(eq, control, target, err, ratio) from None
            continue
        if s.stability and eq.negative:
            handle_unstable(eq, rec, snap, control)
            rate = None
        else:
            rec.record(eq, it, rn, snap)
            if it <= s.desired_iterations + 1:
                h = min(h_max, 2.0 * h)
        if abs(eq.lam - k / steps) < 1e-12:
            k += 1
        elif eq.lam > k / steps:                 # a branch switch or snap went past requested levels
            k = int(np.floor(eq.lam * steps + 1e-9)) + 1


def _settle(eq: Equilibrium, rec: PathRecorder, snap, target: float) -> bool:
    """Newton failed at every step size away from any critical point: the start's tangent sees
    almost none of the stiffness the step mobilises (a flat string or net, stiff only once it
    deflects, overshoots by orders of magnitude from any predictor). Descend the total potential at
    ``target`` instead (:func:`descend`, pseudo-transient continuation) and accept the stable state
    it reaches as the step's end (the path is flagged when the step's work misses its strain
    energy: the state is an equilibrium, the path to it untraced). False, the state restored, when
    the descent fails."""
    try:
        eq.apply(np.zeros(len(eq.free)), target - snap[2])      # the prescribed motions at target too
        eq.lam = target
        it = descend(eq, target, np.zeros(6 * eq.n), 0.0)
        err = rec.step_energy_error(eq, rec.prev, rec.ends(eq))
    except (StepFailed, SolverError) as fail:
        log.debug("settling at lambda %.6g failed (%s)", target, getattr(fail, "reason", fail))
        eq.restore(snap)
        return False
    log.info("step to load factor %.6g: Newton failed at every size, the potential descended to a stable state "
             "(%d iterations)", target, it)
    rec.record(eq, it, float(np.linalg.norm(eq.residual(eq.lam))), snap)
    if err > ENERGY_TOL:
        # an equilibrium, but the path to it is not traced: its work is not verified
        rec.flag(f"the state at load factor {target:.6g} was reached by descending the potential (Newton failed at "
                 "every step size: the start's tangent sees almost none of the stiffness the step mobilises); the "
                 f"step's work misses its strain energy by {100 * err:.3g} %, so the path to it is not verified "
                 "(control='displacement' traces it)")
    return True


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
    t = eq.tangent_vector()
    nt = eq.norm(t)
    if nt == 0.0 or not np.isfinite(nt):
        raise SolverError("control='arclength' needs a reference load or a prescribed motion that moves the frame "
                          f"by a finite amount (the linear response to it has size {nt:.3g})")
    ds0 = nt / steps if arc_length is None else float(arc_length)
    ds = ds0
    ds_min = ds0 / 2.0 ** (s.max_cuts + 10)
    # largest arc: 1000 first arcs, or every node moving by 5 % of the structure size
    ds_max = max(1e3 * ds0, 0.05 * eq.length * np.sqrt(eq.n))
    prev = None                              # previous converged increment (6n,)
    neg = -1 if eq.negative is None else int(eq.negative)
    done = 0
    while done < steps:
        snap = eq.snapshot()
        try:
            arc = checked_arc_step(eq, rec, ds, t, prev, neg)
        except StepFailed as err:
            eq.restore(snap)
            ds *= 0.5
            rec.cuts += 1
            log.debug("arc-length step ds = %.3g failed (%s)", 2 * ds, err.reason)
            if ds < ds_min:
                raise SolverError(f"control='arclength': no converged step at lambda = {snap[2]:.6g} down to an arc "
                                  f"length of {ds:.3g} ({err.reason})") from None
            continue
        lam0 = snap[2]
        if np.sign(arc.slope0) != np.sign(arc.slope1):
            rec.event("limit", locate_limit(eq, snap, t, prev, ds, arc), arc.negative)
        elif s.stability and neg >= 0 and arc.negative > neg and not eq.nonconservative:
            switched = _arc_bifurcation(eq, rec, snap, neg, arc)
            if switched is not None:
                arc = switched
        if lam0 < 1.0 <= eq.lam and land(eq, rec, snap, 1.0):
            rec.record(eq, arc.iterations, arc.residual, snap, arc=True)
            return
        rec.record(eq, arc.iterations, arc.residual, snap, arc=True)
        prev, t, neg = arc.inc, arc.tangent, arc.negative
        done += 1
        ds = min(ds * float(np.clip(np.sqrt(s.desired_iterations / max(arc.iterations, 1)), 0.5, 2.0)), ds_max)
    rec.spent(eq)


def _arc_bifurcation(eq: Equilibrium, rec: PathRecorder, snap, neg0: int, arc):
    """The arc step from ``snap`` raised the inertia without a turn of the load factor. If the
    critical mode is orthogonal to the load (a symmetric bifurcation), record it and step from the
    critical state onto the secondary branch along the mode; returns the new step (its state
    current), or None (the path goes on as it is: recorded as a bifurcation all the same)."""
    here = eq.snapshot()
    mu, modes = eq.lowest_modes(2)
    phi = modes[:, 0]
    q = eq.load_direction()
    cos = abs(float(phi[eq.free] @ q)) / max(float(np.linalg.norm(phi[eq.free]) * np.linalg.norm(q)), 1e-300)
    lam_c = critical_point(eq, snap, here[2], float(mu[0]))
    rec.event("bifurcation", lam_c, arc.negative)
    if cos > ORTHOGONAL:
        eq.restore(here)
        return None
    eq.restore(snap)
    try:
        eq.correct(lam_c)
        if eq.negative:
            raise StepFailed("past the critical point")
    except StepFailed:
        eq.restore(snap)
    rec.record(eq, 0, float(np.linalg.norm(eq.residual(eq.lam))), snap, arc=True)
    mode = mode_along(eq, phi)
    rec.along(eq, mode)             # the path leaves the critical state along the mode
    amp = eq.s.perturbation * eq.length
    start = eq.snapshot()
    for a in (amp, 0.25 * amp, 0.0625 * amp):
        try:
            out = checked_arc_step(eq, rec, a, eq.tangent_vector(), None, -1, predictor=(a * mode, 0.0))
        except StepFailed:
            eq.restore(start)
            continue
        rec.event("switch", eq.lam, arc.negative)
        rec.switches.append((float(start[2]), float(a)))
        log.info("arc length: bifurcation at lambda = %.6g, switched to the secondary branch (perturbation %.3g mm)",
                 lam_c, a)
        return out
    eq.restore(here)
    return None
