"""The large-motion engine on any frame: ``homtex.solve_nonlinear(..., contact=Contact())``.

:class:`EngineStepper` takes an :class:`~homtex.contact.incremental.IncrementalSolver` through
increasing levels of one load parameter: a step that fails is redone as two halves, and so is a
step whose energy ledger does not close (its trapezoidal work misses the energy it stored and
dissipated by more than ``refine`` of its work: too coarse for the path) or whose stabilisation
took more than ``refine`` of the work done on it (a jump inside the step); recursively up to
``max_cuts`` levels deep. A jump that halving does not resolve (the halves fail) is kept as the
single step that passed, and the path is flagged by the ledger check. ``compress``, the seam
functions and :func:`run_engine` all step with it.

:func:`run_engine` is what ``solve_nonlinear`` runs with contact: the load factor lambda goes from
0 to 1 in ``steps`` equal levels and scales, from the start state, the dead loads, the prescribed
motions of ``fixed``, the plates' motions and forces and the pre-strain scale; the path Dataset
records every level with the energy ledger of :mod:`homtex.analysis.energy`, the plates' heights
and forces, contacts, stability and the monitored nodes.
"""

from __future__ import annotations

import logging
import time
from dataclasses import replace
from typing import Callable

import numpy as np
import xarray as xr

from ..analysis.energy import LEDGER_META, ledger_check
from ..analysis.nonlinear import NonlinearResult
from ..analysis.records import DOFS, ENERGY_NAMES
from ..errors import InputError, SolverError
from ..model.results import Status, set_status
from ..model.scene import Plate, parse_fixed, parse_loads
from ..output.datasets import curve_dataset
from ..output.progress import Progress
from .incremental import EngineState, IncrementalSolver, NonlinearSettings, StepInfo
from .options import Contact

__all__ = ["FRICTION_STEPPING", "PATH_STEPPING", "EngineStepper", "run_engine"]

log = logging.getLogger(__name__)

#: an eigenvalue of the scaled Hessian below -NEGATIVE is a buckling state (not round-off)
NEGATIVE = 1e-11

_LEDGER = ("external_work", "prestrain_work", "strain_energy", "contact_energy", "dissipation", "stabilization")


# the stepping of long loaded paths with snaps (knit tensile tests, a sewn cell under the punch):
# snaps localised to 5 halvings, each step started at the last sub-step size that passed; measured
# there to give the full bisection's curves (tests/test_knits.py) at a fraction of its cost
PATH_STEPPING = {"max_refine": 5, "memory": True}
# knit tensile tests with friction: the regularisation slip halved with the step (see EngineStepper),
# and two halvings more: where contacts start to slide from rest (a tensile test's first level) the
# external work's trapezoid misses about half the first sub-step's friction work, and each halving
# halves it (the acrylic rib across, first 2 % level: balance -1.21 / -0.61 / -0.18 % with 5 / 6 / 8
# halvings, the forces the same to 4 digits)
FRICTION_STEPPING = {**PATH_STEPPING, "max_refine": 7, "slip_per_step": True}


class EngineStepper:
    """Adaptive stepping of an :class:`IncrementalSolver` through increasing levels.

    Parameters
    ----------
    sol : the solver (its state is the start of the path).
    solve : ``solve(level) -> StepInfo``: one solver step to ``level`` (SolverError leaves the
        state unchanged).
    max_cuts : halvings of a step, at most (depth of the recursion).
    refine : a step whose imbalance or stabilisation exceeds this share of its work is halved.
    on_accept : called with the StepInfo of every accepted sub-step; whatever it returns is kept in
        ``accepted`` (rolled back with the sub-steps a refinement replaces).
    max_refine : halvings, at most, for accuracy (``refine``; default ``max_cuts``): past it a step
        that still releases energy is kept (a snap: a jump of the path that no step size resolves,
        whose energy goes to the ledger's stabilisation); failures are still halved to ``max_cuts``.
    memory : start a step at the sub-step size that last passed, doubled (not at the whole step):
        on a path whose hard stretch spans several levels, each level's doomed coarse tries (solved
        to equilibrium, then rolled back) are skipped. The levels are on the same halving grid.
    slip_per_step : halve the friction's regularisation slip with every halving of a step (a slip
        rate, as IPC's eps_v dt): the path no longer depends on the subdivision where sub-steps
        slide contacts by about the slip (thick compressible yarns: the acrylic rib across at 2 %
        read 0.024 / 0.010 / 0.0056 N/mm with 5 / 8 / 10 halvings at a fixed slip, 0.0294 with
        each). Off by default: on the spacer's thin yarns it moved the seamed d = 24 mm press by
        0.1 % at twice the CPU, and the main job's strip of three seams failed at 44 % after 2033 s
        (733 s to 50 % without it; docs/contact.md).

    A step that stalls on buckling beams, or converges to a state with a negative eigenvalue (a
    perfect structure past its bifurcation), is left along the critical mode by half the
    thinnest contact radius (cut by the collision check) and taken again: ``events`` records
    each such perturbation (level, amplitude in mm).
    """

    def __init__(self, sol: IncrementalSolver, solve: Callable[[float], StepInfo], *, max_cuts: int = 4,
                 refine: float = 0.01, on_accept: Callable[[StepInfo], object] | None = None, start: float = 0.0,
                 max_refine: int | None = None, memory: bool = False, slip_per_step: bool = False):
        self.sol, self._solve = sol, solve
        self.max_cuts, self.refine = int(max_cuts), float(refine)
        self.max_refine = self.max_cuts if max_refine is None else min(int(max_refine), self.max_cuts)
        self.memory = bool(memory)
        self.slip_per_step = bool(slip_per_step)
        self.hint = 0                    # depth the next try starts at (memory)
        self.on_accept = on_accept
        self.level = float(start)
        self.accepted: list = []
        self.totals = {"iterations": 0, "factorisations": 0, "substeps": 0}
        self.events: list = []           # (level at the step's start, perturbation applied, mm)
        self.perturbation = 0.5 * float(sol.frame.contact_radius.min())

    def advance(self, level: float, depth: int = 0) -> StepInfo:
        """Reach ``level`` from the current one (SolverError when a step fails at every depth)."""
        if self.memory and depth < min(self.hint, self.max_cuts):
            return self._halves(level, depth)
        L = self.sol.ledger
        before = {k: L[k] for k in _LEDGER}
        cp = self.sol.checkpoint()
        n0 = len(self.accepted)
        totals0 = dict(self.totals)
        try:
            info = self._solve(level)
        except SolverError:
            info = self._leave_along_mode(level) if self.sol.failure_indefinite else None
            if info is None:
                if depth >= self.max_cuts:
                    raise
                return self._halves(level, depth)
        if info.negative_eigenvalues > 0:
            info = self._restabilize(level, info)
        self._accepted(info)
        if depth < self.max_refine and self._too_coarse({k: L[k] - before[k] for k in _LEDGER}):
            done, coarse, totals1 = self.sol.checkpoint(), self.accepted[n0:], dict(self.totals)
            self.sol.rollback(cp)
            del self.accepted[n0:]
            self.totals = totals0
            try:
                return self._halves(level, depth)
            except SolverError:             # halving does not resolve the jump: keep the step that passed
                self.sol.rollback(done)
                self.accepted[n0:] = coarse
                self.totals = totals1
        self.level = level
        self.hint = max(depth - 1, 0)
        return info

    def _leave_along_mode(self, level: float) -> StepInfo | None:
        """A step that failed on an indefinite Hessian (beams buckling at a symmetric state): leave
        the step's start along its critical mode (the lowest of its Hessian: near a bifurcation, the
        buckling mode; a recorded perturbation), let it settle there and take the step again; None
        when that fails (the start restored)."""
        cp = self.sol.checkpoint()
        _, mode = self.sol.critical_mode()
        try:
            self._kick_and_settle(mode)
            return self._solve(level)
        except SolverError:
            self.sol.rollback(cp)
            self.events.pop()
            return None

    def _restabilize(self, level: float, info: StepInfo, tries: int = 3) -> StepInfo:
        """An accepted state whose Hessian has a negative eigenvalue (a saddle the step converged
        to: a perfect structure past its bifurcation) is left along the critical mode and settles,
        up to ``tries`` times; an unstable state that remains is kept (the path shows its negative
        eigenvalues)."""
        for _ in range(tries):
            mu, mode = self.sol.critical_mode()
            if not mu < -NEGATIVE:
                if mu > -NEGATIVE:
                    info.negative_eigenvalues = 0
                return info
            cp = self.sol.checkpoint()
            try:
                info = self._kick_and_settle(mode)
            except SolverError:
                self.sol.rollback(cp)
                self.events.pop()
                return info
        return info

    def _kick_and_settle(self, mode: np.ndarray) -> StepInfo:
        """Perturb along ``mode`` by ``perturbation`` (cut by the collision check) and solve again at
        the current level: the state falls to a stable one nearby. Nothing moves the supports or
        plates, so no work is done: what the stored energy loses on the way (perturbation and fall
        together) is what the jump released, and that is the stabilisation it adds to the ledger."""
        sol = self.sol
        L = sol.ledger
        before = {k: L[k] for k in ("strain_energy", "contact_energy", "dissipation", "stabilization",
                                    "external_work")}
        amp = sol.perturb(mode, self.perturbation)
        self.events.append((float(self.level), float(amp)))
        info = sol.solve()
        d = {k: L[k] - before[k] for k in before}
        L["stabilization"] = before["stabilization"] + d["external_work"] - (
            d["strain_energy"] + d["contact_energy"] + d["dissipation"])
        log.info("engine: a buckling state at level %.6g left along its critical mode (perturbation %.3g mm)",
                 self.level, amp)
        return info

    def _too_coarse(self, d: dict) -> bool:
        dw = d["external_work"] + d["prestrain_work"]
        stored = (d["strain_energy"], d["contact_energy"], d["dissipation"])
        rest = dw - sum(stored) - d["stabilization"]
        scale = max(abs(dw), *(abs(v) for v in stored))
        if scale <= self.sol.energy_floor:
            return False
        if dw != 0.0 and d["stabilization"] > self.refine * abs(dw):
            return True
        return abs(rest) > self.refine * scale

    def _accepted(self, info: StepInfo) -> None:
        self.totals["iterations"] += info.iterations
        self.totals["factorisations"] += info.iterations + info.projected + 1
        self.totals["substeps"] += 1
        if self.on_accept is not None:
            self.accepted.append(self.on_accept(info))

    def _halves(self, level: float, depth: int) -> StepInfo:
        eps = self.sol.eps_v
        if self.slip_per_step:
            self.sol.eps_v = 0.5 * eps
        try:
            mid = 0.5 * (self.level + level)
            self.advance(mid, depth + 1)
            return self.advance(level, depth + 1)
        finally:
            self.sol.eps_v = eps

    def take_totals(self) -> dict:
        out, self.totals = self.totals, {"iterations": 0, "factorisations": 0, "substeps": 0}
        return out


# ---------------------------------------------------------------------------------------------
_PATH_META = {
    "load_factor": ("1", "load factor lambda (loads, prescribed motions, plate motions and forces, pre-strain ramp)"),
    "stable": ("1", "state stable: the Hessian of the total potential on the free DOFs is positive definite"),
    "negative_eigenvalues": ("1", "negative eigenvalues of the Hessian of the total potential (LDL^T inertia)"),
    "iterations": ("1", "Newton iterations of the level (all its sub-steps and friction rounds)"),
    "substeps": ("1", "steps the level needed (1: none; more after halving)"),
    "residual": ("N", "out-of-balance force on the free DOFs at convergence (2-norm)"),
    "prestrain_scale": ("1", "factor on the frame's pre-strain"),
    **{k: ("N mm", f"{k.replace('_', ' ')} strain energy, sum over elements") for k in ENERGY_NAMES},
    **LEDGER_META,
    "active_yarn_yarn": ("1", "yarn-yarn segment pairs within the barrier's activation gap"),
    "active_yarn_plate": ("1", "nodes within the barrier's activation gap of a plate"),
    "min_gap": ("mm", "smallest yarn-yarn or yarn-plate gap (surface to surface)"),
    "max_axial_strain": ("1", "largest |axial strain| N / EA of any element"),
    "strain_exceeded": ("1", "an element's axial or shear strain is beyond its strain_limit"),
}


class _Run:
    """The levels of one :func:`run_engine` call: solver, level map and recorded rows."""

    def __init__(self, sol: IncrementalSolver, plates0, plate_motion, force0, force1, s0, s1, monitor, n_ramp):
        self.sol = sol
        self.z0, self.motion_z = plates0, plate_motion
        self.f0, self.f1 = force0, force1
        self.s0, self.s1 = s0, s1
        self.monitor = monitor
        self.n_ramp = n_ramp
        self.rows: list[dict] = []

    def solve(self, lam: float) -> StepInfo:
        sol = self.sol
        kw = {"motion": lam, "loads": lam}
        fc = sol.plates.force_controlled
        if len(fc):
            kw["plate_z"] = np.where(fc, np.nan, self.z0 + lam * self.motion_z)
            if fc.any():
                kw["plate_force"] = {int(p): float(self.f0[p] + lam * (self.f1[p] - self.f0[p]))
                                     for p in np.flatnonzero(fc)}
        if self.s1 is not None:
            kw["prestrain_scale"] = self.s0 + lam * (self.s1 - self.s0)
        return sol.solve(**kw)

    def record(self, lam: float, info: StepInfo, totals: dict) -> None:
        sol = self.sol
        ev = info.extra["ev"]
        L = sol.ledger
        E = sol.cor.energy.sum(axis=0)
        axial, shear, _ = sol.cor.strains()
        limit = np.asarray(sol.frame.strain_limit, dtype=float)
        gaps = np.r_[ev["pairs"].gap, ev["plates"]["gap"]]
        neg = int(info.negative_eigenvalues)
        r = {"load_factor": lam, "stable": neg == 0, "negative_eigenvalues": neg,
             "iterations": totals["iterations"], "substeps": totals["substeps"], "residual": info.residual,
             "prestrain_scale": sol.prestrain_scale, **dict(zip(ENERGY_NAMES, (float(v) for v in E))),
             "external_work": L["external_work"], "prestrain_work": L["prestrain_work"],
             "strain_energy": L["strain_energy"], "contact_energy": L["contact_energy"],
             "friction_energy": L["dissipation"], "stabilization_energy": L["stabilization"],
             "energy_balance": sol.balance(), "active_yarn_yarn": ev["pairs"].n_active,
             "active_yarn_plate": len(ev["plates"]["active"]),
             "min_gap": float(gaps.min()) if gaps.size else np.inf,
             "max_axial_strain": float(np.abs(axial).max(initial=0.0)),
             "strain_exceeded": bool(np.any((np.abs(axial) > limit) | (shear > limit)))}
        react = info.extra["reactions"]
        if sol.lat is not None:
            r["periods"] = sol.lat.periods.copy()
            r["lattice_force"] = react[sol.lat.rows, :3].copy()
        r["plate_z"] = sol.plates.z.copy()
        r["plate_force"] = sol.plates.normal * ev["plates"]["grad_plate"] if sol.P else np.zeros(0)
        r["u"] = sol.cor.u()[self.monitor]
        r["force"] = react[:sol.n][self.monitor]
        self.rows.append(r)

    def dataset(self, attrs: dict) -> xr.Dataset:
        n = len(self.rows)
        data = {k: ("step", np.array([r[k] for r in self.rows], dtype=float if k not in ("stable", "strain_exceeded")
                                     else bool).reshape(n), *meta) for k, meta in _PATH_META.items()}
        coords = {"step": (np.arange(1, n + 1), "1", "converged level along the path")}
        P = self.sol.P
        if P:
            data["plate_z"] = (("step", "plate"), np.array([r["plate_z"] for r in self.rows]).reshape(n, P), "mm",
                               "plate height")
            data["plate_force"] = (("step", "plate"), np.array([r["plate_force"] for r in self.rows]).reshape(n, P),
                                   "N", "force of the yarns on the plate, pressing it along its normal (compression "
                                        "positive)")
            coords["plate"] = (np.arange(P), "1", "plate")
        if self.sol.lat is not None:
            data.update(_lattice_vars(self.rows, n, self.sol.lat.k))
            coords["vector"] = (np.arange(self.sol.lat.k), "1", "lattice vector")
            coords["component"] = (np.array(["x", "y", "z"]), "1", "Cartesian component")
        m = len(self.monitor)
        if m:
            coords["node"] = (np.asarray(self.monitor), "1", "monitored node")
            coords["dof"] = (np.array(DOFS), "1", "degree of freedom")
            data["u"] = (("step", "node", "dof"), np.array([r["u"] for r in self.rows]).reshape(n, m, 6),
                         "mm (ux, uy, uz), rad (rx, ry, rz)", "displacement of monitored nodes from the frame's "
                                                             "reference geometry; rotations as rotation vectors")
            data["force"] = (("step", "node", "dof"), np.array([r["force"] for r in self.rows]).reshape(n, m, 6),
                             "N (ux, uy, uz), N mm (rx, ry, rz)", "external force on monitored nodes: loads plus "
                                                                  "support reactions")
        return curve_dataset(data, coords, attrs)


def _lattice_vars(rows, n, k) -> dict:
    """Path variables of a moving lattice: the lattice vectors and their generalised forces."""
    return {"periods": (("step", "vector", "component"), np.array([r["periods"] for r in rows]).reshape(n, k, 3),
                        "mm", "lattice vectors of the periodic frame"),
            "lattice_force": (("step", "vector", "component"),
                              np.array([r["lattice_force"] for r in rows]).reshape(n, k, 3), "N",
                              "force on each lattice vector component, dPi/da (the force the cell carries across "
                              "the boundary the vector spans; zero on free components)")}


def _plates_for_run(plates, initial: EngineState | None):
    """(Plate list at the start, (P,) plate motion, (P,) force at lambda 0, (P,) force at 1)."""
    if plates is None:
        if initial is None or not len(initial.plate_z):
            return [], np.zeros(0), np.zeros(0), np.zeros(0)
        out, f = [], []
        for z, nrm, F in zip(initial.plate_z, initial.plate_normal, initial.plate_force):
            fc = bool(np.isfinite(F))
            out.append(Plate(z=float(z), normal=int(nrm), force=float(F) if fc else None,
                             displacement=None if fc else 0.0))
            f.append(float(F) if fc else 0.0)
        f = np.array(f)
        return out, np.zeros(len(out)), f, f.copy()
    plates = list(plates)
    for i, p in enumerate(plates):
        if not isinstance(p, Plate):
            raise InputError(f"plates[{i}] must be a homtex.Plate, got {type(p).__name__}")
    motion = np.array([0.0 if p.force_controlled else float(p.displacement or 0.0) for p in plates])
    f1 = np.array([float(p.force) if p.force_controlled else 0.0 for p in plates])
    f0 = np.zeros(len(plates))
    start = [replace(p, force=0.0) if p.force_controlled else replace(p, displacement=0.0) for p in plates]
    return start, motion, f0, f1


def run_engine(frame, fixed=None, loads=None, *, contact: Contact, plates=None, steps: int = 10,
               prestrain: float | None = None, initial: EngineState | None = None, friction_spec: dict | None = None,
               max_cuts: int = 10, refine: float = 0.003, settings: NonlinearSettings | None = None, monitor=None,
               progress: bool = False, rest=None, lattice=None) -> NonlinearResult:
    """Follow lambda from 0 to 1 in ``steps`` levels with the large-motion engine (see the module
    docstring and :func:`homtex.solve_nonlinear`); SolverError names the level that failed (its
    ``result`` attribute holds the path up to it)."""
    t0 = time.perf_counter()
    n = frame.n_nodes
    start_plates, motion_z, f0, f1 = _plates_for_run(plates, initial)
    s0 = float(initial.prestrain_scale) if initial is not None else (0.0 if prestrain is not None else 1.0)
    sol = IncrementalSolver(frame, fixed, loads, start_plates, contact, friction_spec=friction_spec, settings=settings,
                            initial=initial, prestrain_scale=s0, rest=rest, lattice=lattice)
    mask, ubar = parse_fixed(fixed, n)
    f = parse_loads(loads, n)
    driven = bool(np.any(ubar != 0.0) or np.any(f != 0.0) or np.any(motion_z != 0.0) or np.any(f1 != f0) or
                  (prestrain is not None and float(prestrain) != s0) or (sol.lat is not None and sol.lat.driven))
    if monitor is None:
        monitor = np.flatnonzero(np.any((f != 0.0).reshape(n, 6) | (ubar != 0.0).reshape(n, 6), axis=1))
    run = _Run(sol, np.array([p.z for p in start_plates], dtype=float), motion_z, f0, f1, s0,
               None if prestrain is None else float(prestrain), np.asarray(monitor, dtype=np.int64), steps)
    stepper = EngineStepper(sol, run.solve, max_cuts=max_cuts, refine=refine)
    bar = Progress(steps, "engine steps", enabled=progress)
    status, detail, failure = Status.OK, "", None
    for k in range(1, steps + 1):
        lam = k / steps
        try:
            info = stepper.advance(lam)
        except SolverError as err:
            status = Status.FAILED
            detail = (f"failed at step {k} of {steps} (load factor {lam:.4g}, also after halving the step {max_cuts} "
                      f"times): {err}")
            failure = err
            break
        run.record(lam, info, stepper.take_totals())
        bar.step()
    bar.close()
    attrs = {"engine": "large-motion contact (co-rotational beams, IPC barrier, lagged friction, PTC)",
             "control": "load", "steps": int(steps), "max_cuts": int(max_cuts), "refine": float(refine),
             "barrier_gap_mm": sol.ghat, "barrier_stiffness_N_per_mm": sol.kappa, "friction_slip_mm": sol.eps_v,
             "friction_max": float(max(sol.scene.mu_table.max(initial=0.0), sol.scene.mu_plate.max(initial=0.0))),
             "initial_touching_pairs": sol.scene.initial_touching, "continued": initial is not None,
             "driven": driven, "seconds": time.perf_counter() - t0,
             "branch_switches": np.array(stepper.events, dtype=float).reshape(-1),
             "branch_switches_note": "pairs (load factor at the step's start, perturbation along the critical mode "
                                     "in mm) of every state left along a critical mode"}
    ds = run.dataset(attrs)
    if status is Status.OK and len(run.rows):
        check = ledger_check(ds.external_work.values, ds.prestrain_work.values, ds.stabilization_energy.values,
                             ds.energy_balance.values, ds.load_factor.values, driven=driven,
                             floor=sol.energy_floor, friction_energy=ds.friction_energy.values)
        if check:
            status, detail = Status.FLAGGED, check
            log.warning("solve_nonlinear: %s", check)
    set_status(ds, status, detail)
    result = _result(sol, ds, run)
    if failure is not None:
        err = SolverError(f"solve_nonlinear (contact): {detail}")
        err.result = result
        raise err from failure
    return result


def _result(sol: IncrementalSolver, path: xr.Dataset, run: _Run) -> NonlinearResult:
    n = sol.n
    react = sol._react[:n]
    reactions = np.where(sol.mask[:6 * n].reshape(n, 6), react - sol.applied_loads(), 0.0)
    neg = int(run.rows[-1]["negative_eigenvalues"]) if run.rows else -1
    lam = float(run.rows[-1]["load_factor"]) if run.rows else 0.0
    u = sol.cor.u()
    history = [(float(r["load_factor"]), int(r["iterations"]), float(r["residual"])) for r in run.rows]
    return NonlinearResult(frame=sol.frame, u=u, x=sol.positions.copy(), Q=sol.cor.Q.copy(),
                           forces=sol.cor.forces.copy(), energy=dict(zip(ENERGY_NAMES, sol.cor.energy.T.copy())),
                           reactions=reactions, path=path, load_factor=lam, stable=neg == 0,
                           negative_eigenvalues=neg, critical_load_factor=float("nan"), history=history,
                           state=sol.export_state(), plate_z=sol.plates.z.copy())
