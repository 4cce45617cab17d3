"""Quasi-static steps of a co-rotational frame with large-motion contact and friction.

:class:`IncrementalSolver` holds a state (translations, rotations, plate heights, load factor,
pre-strain scale) and takes it to the equilibrium of the next prescribed level (or raises
SolverError with the state unchanged). Each step minimises one potential over translations and
nodal spins,

    Pi = U (co-rotational beams, :class:`~homtex.analysis.corotational.Corotational`)
       + B (IPC barrier, yarn-yarn and yarn-plate, :mod:`.ipc_scene`)
       + D (lagged smoothed Coulomb friction over the step, :mod:`.friction`) - f_ext . u,

by Newton's method with pseudo-transient continuation (PTC, Kelley and Keyes 1998): the
system is (H + M / delta) du = -g, H the symmetric part of the consistent beam tangent plus the
PSD contact and friction blocks, M a lumped diagonal of the beam tangent (frozen per step),
delta the pseudo-time step adapted like a trust region (it grows tenfold after a full step whose
decrease of Pi the quadratic model predicted, a hundredfold after two in a row; it shrinks when
the factor shows negative pivots or the line search cuts). PTC changes the path to an
equilibrium, not the equilibrium. The energy the pseudo-viscous term absorbs at fixed prescribed
motions (sum du^T M du / delta) is recorded: large where the state jumps at a fixed plate position
(snap-through, a buckling leg).

Every trial state is intersection-free: the step length is capped by the additive CCD of
:mod:`.ccd` (candidates searched again before a step can reach a pair outside the list) and the
exact plate bound; prescribed motions enter the first iterations as part of the Newton step (a
predictor cut by the CCD), then Newton corrects with an Armijo line search on Pi.

Friction is lagged: normal forces and tangent bases frozen at the step's start, re-lagged at
the converged state until the nodes' normal forces settle (``friction_rounds``; the rounds before
the settled one are solved to ``round_tol`` only). The energy it dissipates over a step is the work
of its forces along the straight path of the step.

Energy bookkeeping (cumulative, per accepted state): external work (trapezoidal), strain energy
split, contact energy, friction dissipated, stabilisation absorbed, pre-strain work, the balance.
"""

from __future__ import annotations

import logging

import numpy as np

from ..analysis.corotational import Corotational, element_loop_serial
from ..errors import InputError, SolverError
from ..fem.corotational_system import apply_increment
from ..model.frame import Frame
from ..model.scene import Scene, parse_loads
from .ccd import pair_step_bound, plate_step_bound
from .friction import friction_potential
from .ipc_scene import PlateState
from .ipc_system import SystemMixin, _StepFailed, lag_change, serial_numba
from .lattice import Lattice, LatticeDriver, LatticeMixin, image_motion
from .options import Contact
from .step_data import EngineState, NonlinearSettings, StepInfo

log = logging.getLogger(__name__)

__all__ = ["EngineState", "IncrementalSolver", "NonlinearSettings", "StepInfo"]


class IncrementalSolver(SystemMixin, LatticeMixin):
    """Large-rotation frame with large-motion contact and friction, stepped quasi-statically.

    Parameters
    ----------
    frame : homtex.Frame (finite, 1- or 2-periodic; periodic images keep their offsets).
    fixed : supports as in ``solve_static`` (dict values: prescribed at load factor 1).
    loads : dead nodal loads at load factor 1 (N, N mm).
    plates : homtex.Plate list (rigid planes normal to z; ``force`` set: force control, the
        plate's height is an unknown). Each plate's ``z`` is its starting height.
    contact : homtex.Contact (barrier_gap, barrier_stiffness, friction, friction_slip, margin).
    friction_spec : a cell file's friction (:meth:`homtex.Cell.friction_spec`), used when
        ``contact.friction`` is None.
    settings : :class:`NonlinearSettings`.
    initial : an :class:`EngineState` of an earlier solve of the same frame to continue from
        (positions, rotations, pre-strain scale, applied loads, the reference pairs' touch offsets,
        the PTC step and the energy ledger); the loads at load factor 0 are then its loads (the
        ``loads`` given here are added on top, scaled by the load factor).
    prestrain_scale : the factor on the frame's pre-strain at the start (default 1, or the
        initial state's).
    rest : a :class:`~homtex.model.rest.RestState`: the yarns' stress-free shape when it is not
        the start geometry (energies count from it).
    lattice : a :class:`~homtex.contact.lattice.Lattice` (periodic frames): lattice vectors as
        unknowns, held, prescribed (``motion`` scaled by the motion factor) or free, after the
        plates in the DOF arrays (rows n + P ...).
    """

    def __init__(self, frame: Frame, fixed=None, loads=None, plates=(), contact: Contact | None = None, *,
                 friction_spec: dict | None = None, settings: NonlinearSettings | None = None,
                 initial: EngineState | None = None, prestrain_scale: float | None = None, rest=None,
                 lattice: Lattice | None = None):
        if not isinstance(frame, Frame):
            raise InputError(f"frame must be a homtex.Frame, got {type(frame).__name__}")
        contact = Contact() if contact is None else contact
        if not isinstance(contact, Contact):
            raise InputError(f"contact must be a homtex.Contact, got {type(contact).__name__}")
        self.s = settings or NonlinearSettings()
        self.frame = frame
        self.contact = contact
        sc = Scene.build(frame, fixed, loads, plates)
        n, P = frame.n_nodes, len(sc.plates)
        k = frame.dim_periodic if lattice is not None else 0
        self.n, self.P, self.N = n, P, n + P + k
        if initial is not None:
            initial.check(frame)
        if lattice is not None:
            self.lat = LatticeDriver(frame, lattice, n + P, None if initial is None else initial.periods)
        fc = np.array([p.force_controlled for p in sc.plates], dtype=bool)
        self.plates = PlateState(z=np.array([float(p.z) for p in sc.plates]),
                                 normal=np.array([int(p.normal) for p in sc.plates]), force_controlled=fc)
        self._contact_setup(frame, contact, friction_spec, initial)
        mask = np.ones((self.N, 6), dtype=bool)
        mask[:n] = sc.mask.reshape(n, 6)
        mask[n:n + P, 2] = ~fc
        if self.lat is not None:
            mask[self.lat.rows, :3] = self.lat.held
        self.mask = mask.ravel()
        self.free = np.flatnonzero(~self.mask)
        self.ubar = np.where(sc.mask, sc.values, 0.0).reshape(n, 6)
        self.f_loads = sc.loads.reshape(n, 6)
        self.f_base = np.zeros((n, 6))         # loads at load factor 0 (those of a continued solve)
        self.plate_force = np.array([p.normal * p.force if p.force_controlled else 0.0 for p in sc.plates])
        self.cor = Corotational(frame, geometric="consistent", rest=rest)
        if self.lat is not None:
            self.cor.shift[...] = self.lat.shifts()
        self.motion = 0.0
        self.presc = np.zeros((n, 6))          # prescribed DOFs moved since the start (mm, rad)
        self.load_scale = 0.0
        self.prestrain_scale = 1.0
        self.delta = self.s.delta0
        self._trusted = False       # the last Newton step agreed with its quadratic model (:meth:`_adapt`)
        if initial is not None:
            self.cor.ut[...] = initial.ut
            self.cor.Q[...] = initial.Q
            self.prestrain_scale = float(initial.prestrain_scale)
            self.f_base = np.array(initial.loads, dtype=float).reshape(n, 6)
            self.delta = min(float(initial.delta), self.s.delta_max)
        if prestrain_scale is not None:
            self.prestrain_scale = float(prestrain_scale)
        self.small = element_loop_serial(frame.n_elements)
        self.sys = None
        self._coupled = np.zeros((0, 2), dtype=np.int64)
        self.M = None
        self.terms: list = []       # extra potentials scaled with the pre-strain (:meth:`add_term`)
        self.info = StepInfo()
        self.failure_indefinite = False
        self._hmax = 0.0            # largest diagonal entry of the last assembled Hessian
        self._hsize = float(np.mean(frame.length))
        with serial_numba(self.small):
            self.scene.search(self.positions)
            self._pattern()
            self._start_ledger()
        if initial is not None:
            for k in ("external_work", "prestrain_work", "dissipation", "stabilization", "U0", "B0"):
                self.ledger[k] = float(initial.ledger[k])
            self.ledger["strain_energy"] = self._ev0["U"] - self.ledger["U0"]
            self.ledger["contact_energy"] = self._ev0["B"] - self.ledger["B0"]

    def add_term(self, term) -> None:
        """Add a potential scaled by the pre-strain scale (a :class:`~homtex.contact.tension.ConstantTension`
        thread) and restart the energy ledger (call before the first step)."""
        self.terms.append(term)
        with serial_numba(self.small):
            self._start_ledger()

    def restart_at(self, ut: np.ndarray, Q: np.ndarray) -> None:
        """Move to the translations ``ut`` (n, 3, mm) and rotations ``Q`` (n, 3, 3) of an earlier solve of the
        same frame and start the energy ledger there (a new path; the contacts are searched again)."""
        self.cor.ut[...] = ut
        self.cor.Q[...] = Q
        with serial_numba(self.small):
            self.scene.search(self.positions)
            self._pattern()
            self._start_ledger()

    # ------------------------------------------------------------------ state
    @property
    def positions(self) -> np.ndarray:
        """(n, 3) current node positions, mm."""
        return self.frame.nodes + self.cor.ut

    @property
    def plate_z(self) -> np.ndarray:
        """(P,) current plate heights, mm."""
        return self.plates.z.copy()

    def snapshot(self):
        return (self.cor.ut.copy(), self.cor.Q.copy(), self.plates.z.copy(), self.motion, self.prestrain_scale,
                self.delta, self.plate_force.copy(), self.load_scale, self.presc.copy(),
                None if self.lat is None else self.lat.periods.copy())

    def applied_loads(self) -> np.ndarray:
        """(n, 6) dead loads at the current load factor (N, N mm)."""
        return self.f_base + self.load_scale * self.f_loads

    def export_state(self) -> EngineState:
        """The state to continue from in another solve of the same frame (:class:`EngineState`)."""
        sc = self.scene
        return EngineState(n_nodes=self.n, n_elements=self.frame.n_elements, ut=self.cor.ut.copy(),
                           Q=self.cor.Q.copy(), prestrain_scale=float(self.prestrain_scale),
                           loads=self.applied_loads().copy(), plate_z=self.plates.z.copy(),
                           plate_normal=self.plates.normal.copy(),
                           plate_force=np.where(self.plates.force_controlled, self.plates.normal * self.plate_force,
                                                np.nan),
                           touch=(sc.touch_keys.copy(), sc.touch_rsum.copy(), sc.touch_gap.copy()),
                           ledger=dict(self.ledger), delta=float(self.delta),
                           periods=None if self.lat is None else self.lat.periods.copy())

    def set_loads(self, loads) -> None:
        """Replace the dead loads (dict node -> (Fx, Fy, Fz, Mx, My, Mz), N and N mm, scaled by the
        load factor) from the next step on."""
        self.f_loads = parse_loads(loads, self.n).reshape(self.n, 6)

    def checkpoint(self):
        """State and energy ledger, to hand back to :meth:`rollback` (undo accepted steps)."""
        return self.snapshot(), dict(self.ledger), self._react.copy(), self._dUds

    def rollback(self, cp) -> None:
        self.restore(cp[0])
        self.ledger.clear()
        self.ledger.update(cp[1])
        self._react, self._dUds = cp[2].copy(), cp[3]

    def restore(self, snap) -> None:
        self.cor.ut[...] = snap[0]
        self.cor.Q[...] = snap[1]
        self.plates.z[...] = snap[2]
        self.motion, self.prestrain_scale, self.delta = snap[3], snap[4], snap[5]
        self.plate_force[...] = snap[6]
        self.load_scale = snap[7]
        self.presc[...] = snap[8]
        if self.lat is not None:
            self._set_periods(snap[9])
            # the prescribed components' target of the restored motion factor: a step that failed
            # had set its own, and a settling solve at the restored level (the stepper's kick along
            # a critical mode) must not go on to drive the lattice there
            self.lat.set_target(self.motion)

    # ------------------------------------------------------------------ public step
    def solve(self, *, motion: float | None = None, loads: float | None = None, plate_z=None, plate_force=None,
              prestrain_scale: float | None = None, prescribed: dict | None = None) -> StepInfo:
        """Take the state to equilibrium at the given levels; SolverError leaves it unchanged.
        Levels not given keep their current values (all start at 0; the pre-strain scale at 1).

        motion : factor on the prescribed support values of ``fixed`` (mm, rad: rotations are
        spins about the fixed axes). prescribed : {node: {dof: value}} values of supported DOFs at
        the end of this step (mm, rad), overriding ``motion`` for them (paths that are not
        straight). loads : factor on the dead loads. plate_z : {plate: height}
        (or (P,) array, NaN for force-controlled ones) of displacement-controlled plates, mm.
        plate_force : {plate: force pressing it on the yarns} of force-controlled plates, N.
        prestrain_scale : factor on the frame's pre-strain.
        """
        target_z = self.plates.z.copy()
        if plate_z is not None:
            items = plate_z.items() if isinstance(plate_z, dict) else enumerate(np.asarray(plate_z, dtype=float))
            for p, v in items:
                if self.plates.force_controlled[p]:
                    if np.isfinite(v):
                        raise InputError(f"plate {p} is force-controlled: give its force, not its height")
                    continue
                target_z[p] = float(v)
        snap = self.snapshot()
        try:
            if plate_force is not None:
                for p, v in (plate_force.items() if isinstance(plate_force, dict) else enumerate(plate_force)):
                    if not self.plates.force_controlled[p]:
                        raise InputError(f"plate {p} is displacement-controlled: give its height, not a force")
                    self.plate_force[p] = self.plates.normal[p] * float(v)
            if prestrain_scale is not None:
                self.prestrain_scale = float(prestrain_scale)
            target = self.presc.copy()
            if motion is not None:
                self.motion = float(motion)
                target = np.where(self.mask[:6 * self.n].reshape(self.n, 6), self.motion * self.ubar, 0.0)
                if self.lat is not None:
                    self.lat.set_target(self.motion)
            for node, spec in (prescribed or {}).items():
                for dof, v in spec.items():
                    if not self.mask[6 * node + dof]:
                        raise InputError(f"prescribed: node {node} DOF {dof} is not supported (give it in fixed)")
                    target[node, dof] = float(v)
            if loads is not None:
                self.load_scale = float(loads)
            with serial_numba(self.small):
                info = self._step(target, target_z)
                self._account(info, snap)
        except (_StepFailed, SolverError, FloatingPointError, np.linalg.LinAlgError) as err:
            # a step that met buckling beams (an indefinite Hessian): the stepper may leave the start
            # state along its critical mode
            self.failure_indefinite = bool(self.info.extra.get("indefinite"))
            self.restore(snap)
            raise SolverError(str(err)) from None
        return info

    # ------------------------------------------------------------------ the step
    def _step(self, target_u: np.ndarray, target_z: np.ndarray) -> StepInfo:
        self.info = info = StepInfo()
        x_start = self.positions.copy()
        z_start = self.plates.z.copy()
        self._p_start = None if self.lat is None else self.lat.periods.copy()
        self.delta = min(self.delta, self.s.delta_max)
        self.M = None
        lag = start_lag = self.scene.friction_lag(self._xc(x_start), z_start)
        rounds = self.s.friction_rounds if self.scene.has_friction else 1
        # rounds before the last stop at round_tol: solving each to tol spent a quarter of the 43 mm
        # seamed press's Newton iterations on states the next lag moves anyway
        loose = max(self.s.round_tol / self.s.tol, 1.0)
        for rnd in range(rounds):
            last = rnd == rounds - 1
            self._newton(target_u, target_z, x_start, lag, relax=1.0 if last else loose)
            info.friction_rounds = rnd + 1
            used = lag
            if not self.scene.has_friction:
                break
            lag = self.scene.friction_lag(self._xc(self.positions), self.plates.z)
            info.extra["lag_change"] = lag_change(used, lag, self._n_contact())
            if info.extra["lag_change"] <= self.s.friction_tol:
                if not last and loose > 1.0:
                    self._newton(target_u, target_z, x_start, used)
                    lag = self.scene.friction_lag(self._xc(self.positions), self.plates.z)
                break
        self.lag = used
        ev = self._evaluate(x_start, [lg for lg in used if lg is not None], hessian=True)
        self._assemble(ev)
        self.sys.factor(inertia=True)
        info.negative_eigenvalues = int(self.sys.negative) if self.sys.negative is not None else -1
        if self.scene.has_friction:
            # trapezoidal in the normal forces: those of the step's start and of its end state
            info.dissipation = 0.5 * (self._dissipation(start_lag, x_start) + self._dissipation(lag, x_start))
        info.delta = self.delta
        info.extra.update(ev=ev, x_start=x_start)
        return info

    def _dissipation(self, lag, x_start) -> float:
        """Energy friction dissipates over the step to the current state with the normal forces,
        bases and closest points of ``lag`` (N mm; :func:`~homtex.contact.friction.friction_potential`)."""
        x, x0 = self._xc(self.positions), self._xc(x_start, self._p_start)
        return float(sum(friction_potential(lg, x, x0, self.eps_v, hessian=False).dissipation
                         for lg in lag if lg is not None and len(lg)))

    def _remaining(self, target_u, target_z) -> np.ndarray:
        d = np.zeros((self.N, 6))
        d[:self.n] = target_u - self.presc
        d[self.n:self.n + self.P, 2] = np.where(self.plates.force_controlled, 0.0, target_z - self.plates.z)
        if self.lat is not None:
            d[self.lat.rows, :3] = self.lat.remaining()
        return d

    def _converged(self, ev, rn, relax: float = 1.0) -> bool:
        fc = ev["g_contact"]
        ref = max(float(np.linalg.norm(ev["fint"])), float(np.linalg.norm(fc)),
                  float(np.linalg.norm(self.applied_loads())), float(np.linalg.norm(self.plate_force)))
        floor = 1e-12 * float(np.max(self.frame.EA))
        # round-off of the forces: positions carry eps x their size, the stiffest term (a barrier
        # at a small gap: 1e6-1e8 N/mm) turns that into force (1e-8 N for a 20 mm cell)
        xs = float(np.abs(self.positions).max(initial=1.0))
        noise = 64.0 * np.finfo(float).eps * xs * self._hmax * np.sqrt(max(len(self.free), 1))
        return rn <= relax * self.s.tol * ref + floor + noise

    def _newton(self, target_u, target_z, x_start, lag, relax: float = 1.0) -> None:
        """Newton iterations on the step's potential with the friction ``lag`` until the free residual
        is below ``relax`` x the tolerance (:meth:`_converged`); _StepFailed after max_iter."""
        s, info = self.s, self.info
        self._trusted = False
        lag = [lg for lg in lag if lg is not None]
        r_prev = None
        hist, moves = [], []
        since = 0               # iterations since the exact Hessian was last found indefinite
        for it in range(1, s.max_iter + 1):
            # while the exact Hessian keeps being indefinite, go straight to the projected one and
            # try the exact one again every exact_retry iterations: the 20-filament rib's exact
            # Hessians were indefinite at 78 % of its iterations, each a factorisation thrown away
            project = 0 < since < s.exact_retry
            ev = self._evaluate(x_start, lag, hessian=True, project=project)
            rem = self._remaining(target_u, target_z)
            g = ev["g"].ravel()
            rn = float(np.linalg.norm(g[self.free]))
            if not np.isfinite(rn) or not np.isfinite(ev["Pi"]):
                raise _StepFailed(f"non-finite forces at iteration {it}")
            presc = bool(np.any(rem))
            if not presc and self._converged(ev, rn, relax):
                info.residual = rn
                return
            stagnating = len(hist) >= 20 and min(hist[-10:]) > 0.5 * min(hist[-20:-10])
            if (not presc and stagnating and self._converged(ev, rn, relax=max(relax, 1e3))
                    and self.delta >= self.s.delta_max):
                # Newton circles a soft (nearly neutral) mode at 1e-5 of the forces: as converged as the
                # conditioning allows (the residual is recorded)
                info.residual = rn
                info.extra["stagnated"] = True
                log.debug("step accepted at a stagnating residual %.3e", rn)
                return
            r_prev = rn
            hist.append(rn)
            if (not presc and info.extra.get("indefinite") and len(hist) > 12 and rn > 0.5 * hist[-9]
                    and max(moves[-8:]) < 1e-6 * self._hsize):
                # beams buckling at a symmetric state: nothing moves off it, the residual stays; give
                # up early and let the stepper leave along the critical mode
                raise _StepFailed(f"stalled at iteration {it} on an indefinite Hessian (buckling; out-of-balance "
                                  f"force {rn:.3e})")
            # the exact Hessian where it is positive definite (Newton converges quadratically);
            # else the PSD-projected contact blocks and, if still needed, a smaller delta
            # a predictor (prescribed motion left) mobilises friction over the slip of the step: its
            # stick stiffness at eps_v would hold every contact, and most of them slide over the step
            eps_h = self.s.predictor_slip * float(np.abs(rem[:, :3]).max(initial=0.0)) if presc else 0.0
            if eps_h > self.eps_v and self.scene.has_friction:
                ev = self._evaluate(x_start, lag, hessian=True, project=project, eps_hessian=eps_h)
            self._assemble(ev)
            if project:
                self._factor(it)
                info.projected += 1
                since += 1
            elif not self._factor(it, shrink=False):
                ev = self._evaluate(x_start, lag, hessian=True, project=True, eps_hessian=eps_h)
                self._assemble(ev)
                self._factor(it)
                info.projected += 1
                since = 1
            else:
                since = 0
            rhs = -g
            if presc:
                rhs = rhs - self._hess_times(ev, rem).ravel()
            du = rem.ravel().copy()
            du[self.free] = self.sys.solve(rhs[self.free])
            d = du.reshape(self.N, 6)
            alpha, dPi, slope = self._line_search(ev, d, x_start, lag, presc, it)
            if not presc:
                self._adapt(du[self.free], alpha, dPi, slope, ev["Pi"])
            log.debug("iteration %d: residual %.3e, step %.3g, delta %.2e, max |du| %.3e, active %d/%d", it, rn,
                      alpha, self.delta, float(np.abs(d[:self.n, :3]).max(initial=0.0)), ev["pairs"].n_active,
                      len(ev["plates"]["active"]))
            df = du[self.free] * alpha
            moves.append(alpha * float(np.abs(d[:self.n, :3]).max(initial=0.0)))
            if not presc:
                # the damping work at fixed prescribed motions: energy the pseudo-viscous term takes
                # out while the state relaxes to equilibrium (while the plates move, it only slows
                # the motion they drive); "released": the potential's whole decrease (a relaxation
                # from a state far from equilibrium, whose energy the solver takes out in any case)
                if self.s.stabilization == "released":
                    info.stabilization -= dPi
                else:
                    info.stabilization += float(df @ (self.M * df)) / self.delta
            info.iterations += 1
            if presc:
                self.presc += min(alpha, 1.0) * (target_u - self.presc)
                if alpha >= 1.0:
                    self.presc[...] = target_u
                    self.plates.z[~self.plates.force_controlled] = target_z[~self.plates.force_controlled]
                    if self.lat is not None:
                        self.lat.reach_target()
                        self._set_periods(self.lat.periods)
        raise _StepFailed(f"did not converge in {s.max_iter} iterations (out-of-balance force {r_prev:.3e})")

    def _line_search(self, ev, d, x_start, lag, presc, it) -> float:
        """Step length along d: capped by the rotations, the CCD and (corrector) Armijo on Pi."""
        s, info = self.s, self.info
        x = self.positions
        dx = d[:self.n, :3]
        dz = d[self.n:self.n + self.P, 2]
        dxc = self._disp_c(d)
        spin = float(np.abs(d[:self.n, 3:]).max(initial=0.0))
        amax = min(1.0, s.max_spin / spin) if spin > 0 else 1.0
        move = float(np.sqrt(np.einsum("ij,ij->i", dxc, dxc)).max(initial=0.0))
        if self.lat is not None:            # the neighbouring cells' copies move with the lattice too
            move = max(move, float(np.sqrt(np.einsum("ij,ij->i", dx, dx)).max(initial=0.0))
                       + image_motion(d[self.lat.rows, :3]))
        # a node moves at most half the widest search margin per iteration
        amax = min(amax, 0.5 * (self.max_margin - 2.0 * self.ghat) / move) if move > 0 else amax
        reach = amax * move
        if not self.scene.covers(x, reach):
            self._search(x, min(max(self.scene.margin, 2.2 * reach + 2.0 * self.ghat), self.max_margin))
        st = self.scene.stencil
        a = amax
        if len(st):
            dxc = self._disp_c(d)           # (a search may have added virtual nodes)
            a = min(a, amax * pair_step_bound(self._xc(x), amax * dxc, st, eta=s.eta))
        if self.P:
            pn, pi = self.scene.plate_nodes, self.scene.plate_index
            a = min(a, amax * plate_step_bound(x, amax * dx, pn, self.scene.node_r[pn], self.plates.origins(),
                                                self.plates.normals(), plate=pi,
                                                plate_motion=np.column_stack([np.zeros((self.P, 2)), amax * dz]),
                                                eta=s.eta))
        if a < amax:
            info.ccd_limited += 1
        if a <= 0.0 or (a < 1e-6 and self._stuck()):
            raise _StepFailed(f"the prescribed motion cannot go on without an overlap at iteration {it} (the "
                              f"collision-free step is {a:.2g}: plates closer than a yarn's diameter, or supports "
                              "pushing a yarn through another)")
        g = ev["g"]
        free = self.free
        slope = float(g.ravel()[free] @ d.ravel()[free])
        base = self.snapshot()
        Pi0 = ev["Pi"]
        ext = float(np.sum(self.applied_loads() * d[:self.n])) + float(self.plate_force @ dz)
        if self.lat is not None:
            ext += float(np.sum(self._lattice_loads() * d[self.lat.rows, :3]))
        for _ in range(40):
            self._apply(a, d)
            if presc:
                return a, 0.0, slope
            trial = self._evaluate(x_start, lag, hessian=False)
            dPi = trial["Pi"] - Pi0 - a * ext
            if np.isfinite(trial["Pi"]) and (dPi <= s.armijo * a * slope or
                                             abs(slope) * a < 1e-14 * max(abs(Pi0), 1e-300)):
                return a, dPi, slope
            self.restore(base)
            a *= 0.5
            info.cuts += 1
        raise _StepFailed(f"the line search found no decrease at iteration {it}")

    def _stuck(self) -> bool:
        """True when a gap is down to 1e-6 of ghat (the barrier cannot hold it any closer)."""
        x = self.positions
        g = self.scene.plate_gaps(x, self.plates.z)
        gmin = float(g.min(initial=np.inf))
        if len(self.scene.stencil):
            from .potential import pair_gaps

            gmin = min(gmin, float(pair_gaps(self._xc(x), self.scene.stencil).min()))
        return gmin < 1e-6 * self.ghat

    def _adapt(self, df, alpha, dPi, slope, Pi0) -> None:
        """Pseudo-time step from the quality of the quadratic model (as a Levenberg-Marquardt
        trust region): rho = actual / predicted decrease of Pi; good agreement grows delta
        tenfold (towards Newton), a hundredfold when the previous step agreed too, poor agreement (or
        a line-search cut) shrinks it fourfold."""
        shift = self.M / self.delta
        curv = float(self.sys.matvec(df) @ df) - float(df @ (shift * df))
        model = alpha * slope + 0.5 * alpha * alpha * curv
        if abs(model) <= 1e-12 * max(abs(Pi0), 1e-300):
            rho = 1.0
        else:
            rho = dPi / model if model < 0 else 0.0
        good = rho >= 0.75 and alpha >= 1.0
        if good:
            # a second good step in a row: the damping is left fast (at tenfold, a third of the 43 mm
            # seamed press's Newton iterations were this regrowth's tail, converging linearly)
            self.delta = min(self.delta * (100.0 if self._trusted else 10.0), self.s.delta_max)
        elif rho < 0.25 or alpha < 1.0:
            self.delta = max(self.delta / 4.0, 1e-12)
        self._trusted = good

    def _apply(self, a, d) -> None:
        inc = np.ascontiguousarray(a * d[:self.n])
        apply_increment(self.cor.ut, self.cor.Q, inc)
        self.plates.z += a * d[self.n:self.n + self.P, 2]
        if self.lat is not None:
            self._set_periods(self.lat.periods + a * d[self.lat.rows, :3])
