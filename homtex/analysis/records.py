"""What a path-following solve records at every converged state, and the strain-range monitor.

Per state: load factor, stability (negative eigenvalues of the tangent), Newton iterations and
residual, the strain-energy split summed over the elements (axial, torsion, bending about both
section axes, shear; N mm), the external work (f . du along the path, reactions included,
moments against spins; each step by :func:`~homtex.analysis.energy.hermite_work` from the forces
and path tangents at its ends: fourth order in the step), the energy a snap-through released
(``stabilization_energy``: under load or displacement control the state jumps from a limit point
to the stable branch at the same load factor) and the relative energy balance
(:func:`~homtex.analysis.energy.balance`), the largest axial, shear and bending strains and the
largest deformational rotation. The element is a
small-strain element in a frame that rotates with it: large rotations are exact, strains are not.
Axial or shear strain beyond an element's ``strain_limit`` (:class:`homtex.Frame`, default 0.02)
is warned once per solve (:class:`homtex.errors.StrainWarning` and the log) and recorded per
state (``strain_exceeded``) and in the attribute ``check``.
"""

from __future__ import annotations

import logging
import warnings

import numpy as np
import xarray as xr

from ..errors import StrainWarning
from ..model.results import Status
from .energy import CHECK_LIMIT, balance, hermite_work, ledger_check

log = logging.getLogger(__name__)

DOFS = ("ux", "uy", "uz", "rx", "ry", "rz")
ENERGY_NAMES = ("axial", "torsion", "bending_y", "bending_z", "shear")

VARIABLES = {
    "load_factor": ("1", "load factor lambda (loads and prescribed motions are lambda x their full values)"),
    "stable": ("1", "state stable: the tangent on the free DOFs is positive definite"),
    "negative_eigenvalues": ("1", "number of negative eigenvalues of the tangent on the free DOFs (LDL^T inertia)"),
    "iterations": ("1", "Newton iterations (linear solves) of the step"),
    "residual": ("N", "out-of-balance force on the free DOFs at convergence (2-norm; moments in N mm)"),
    "axial": ("N mm", "axial strain energy, sum over elements"),
    "torsion": ("N mm", "torsional strain energy, sum over elements"),
    "bending_y": ("N mm", "bending strain energy about the local e2 axes, sum over elements"),
    "bending_z": ("N mm", "bending strain energy about the local e3 axes, sum over elements"),
    "shear": ("N mm", "shear strain energy, sum over elements"),
    "strain_energy": ("N mm", "total strain energy minus its initial value"),
    "external_work": ("N mm", "work of loads and reactions along the path (f . du; Hermite steps)"),
    "stabilization_energy": ("N mm", "energy released where the state snapped to the stable branch at a fixed load "
                                     "factor, since the start"),
    "energy_balance": ("1", "(external work - strain energy - energy released by snaps) / the largest of them"),
    "max_axial_strain": ("1", "largest |axial strain| N / EA of any element"),
    "max_shear_strain": ("1", "largest shear strain |V| / kGA of any element"),
    "max_bending_strain": ("1", "largest bending fibre strain of any element (not monitored: beam theory "
                                "holds for finite curvature)"),
    "strain_exceeded": ("1", "an element's axial or shear strain is beyond its strain_limit"),
    "max_deformational_rotation": ("rad", "largest end rotation against the co-rotated element frame "
                                          "(refine the mesh beyond ~0.3)"),
}


class PathRecorder:
    """Collects the converged states of one solve; :meth:`dataset` makes the ``path``."""

    def __init__(self, control: str, steps: int, nodes=()):
        self.nodes = np.asarray(nodes, dtype=np.int64).reshape(-1)
        self.control = control
        self.steps = steps
        self.rows = []
        self.events = []            # (kind, load factor, negative eigenvalues)
        self.switches = []          # (load factor, perturbation along the critical mode, mm)
        self.cuts = 0
        self.initial = None
        self.status = Status.OK
        self.detail = ""
        self.warned = False
        self.first_exceed = None
        self.worst = None

    def start(self, eq):
        """The initial state (lambda = 0, refreshed): reference energy, force, tangent and state."""
        self.initial = eq.snapshot()
        if eq.s.stability and not eq.nonconservative:
            eq.set_neutral()
        self.U0 = float(eq.cor.energy.sum())
        self.work = 0.0
        self.released = 0.0
        self.driven = bool(np.any(eq.f != 0.0) or eq.has_ubar)
        self.prev = self.ends(eq)
        self.u_acc = np.zeros(6 * eq.n)
        self.track = []
        self.limit = np.asarray(eq.frame.strain_limit, dtype=float)
        self.floor = 1e-12 * float(np.max(eq.frame.EA, initial=0.0)) * float(np.sum(eq.frame.length))

    @staticmethod
    def ends(eq, t=None) -> dict:
        """Force, path tangent t (du / dlambda; computed when not given), its force rate K t, the
        strain energy and the state at the current (fresh) state: one end of a step."""
        t = eq.tangent_vector() if t is None else t
        return {"F": eq.fint.copy(), "t": t, "Kt": eq.k_times(t), "snap": eq.snapshot(), "lam": eq.lam,
                "U": float(eq.cor.energy.sum())}

    def along(self, eq, direction: np.ndarray) -> None:
        """The path leaves the last recorded state along ``direction`` (6n,) (a critical mode, not the
        tangent du / dlambda, which is singular there): the Hermite work of the next step uses it."""
        self.prev["t"] = direction.copy()
        self.prev["Kt"] = eq.k_times(direction)

    def event(self, kind: str, lam: float, negative: int):
        self.events.append((kind, float(lam), int(negative)))

    def _stored(self) -> float:
        return self.U0 + (self.rows[-1]["strain_energy"] if self.rows else 0.0)

    def record(self, eq, iterations: int, residual: float, snap=None, arc: bool = False, jump: bool = False):
        """Record the current converged, fresh state (the step started from the last recorded one).
        ``jump``: the state was reached by a snap at a fixed load factor (the loads did work
        lambda f . du, the prescribed motions none; what the strain energy did not take was
        released)."""
        a = self.prev
        du = eq.increment_since(a["snap"])
        b = self.ends(eq)
        U = eq.cor.energy.sum(axis=0)
        dU_step = float(U.sum()) - self._stored()
        if jump:
            # the loads at the state's load factor on the free DOFs; the prescribed DOFs moved by
            # at most the small change of load factor across the jump (trapezoidal there)
            m = eq.mask
            w = eq.lam * float(eq.f[~m] @ du[~m]) + 0.5 * float((a["F"][m] + b["F"][m]) @ du[m])
            self.released += w - dU_step
        else:
            w = self._step_work(eq, a, b, du)
        self.work += w
        self.prev = b
        self.u_acc += du
        if self.nodes.size:
            self.track.append((self.u_acc.reshape(-1, 6)[self.nodes].copy(), eq.fint.reshape(-1, 6)[self.nodes].copy()))
        dU = float(U.sum()) - self.U0
        axial, shear, bend = eq.cor.strains()
        over = (np.abs(axial) > self.limit) | (shear > self.limit)
        neg = -1 if eq.negative is None else int(eq.negative)
        row = {"load_factor": eq.lam, "stable": neg == 0, "negative_eigenvalues": neg, "iterations": iterations,
               "residual": residual, **dict(zip(ENERGY_NAMES, (float(v) for v in U))), "strain_energy": dU,
               "external_work": self.work, "stabilization_energy": self.released,
               "energy_balance": balance(self.work, 0.0, dU, 0.0, 0.0, self.released, floor=self.floor),
               "max_axial_strain": float(np.abs(axial).max()), "max_shear_strain": float(shear.max()),
               "max_bending_strain": float(bend.max()), "strain_exceeded": bool(over.any()),
               "max_deformational_rotation": eq.cor.max_deformational_rotation()}
        self.rows.append(row)
        if over.any():
            self._exceeded(eq, axial, shear, over)

    def step_energy_error(self, eq, a: dict, b: dict) -> float:
        """Relative mismatch of the work and the strain-energy change of a step between the ends
        ``a`` and ``b`` (:meth:`ends`): the Hermite rule's small error on a resolved step of an
        equilibrium path, large when the step spans a jump or an unstable branch."""
        du = eq.increment_since(a["snap"])
        w = self._step_work(eq, a, b, du)
        dU = b["U"] - a["U"]
        scale = max(abs(w), abs(dU))
        return 0.0 if scale <= self.floor else abs(w - dU) / scale

    @staticmethod
    def _step_work(eq, a, b, du) -> float:
        """Hermite work of the step from ``a`` to ``b``, the path tangents scaled to the chord."""
        c = eq.norm(du)
        if c == 0.0:
            return 0.0
        ends = []
        for e in (a, b):
            t = e["t"]
            nt = eq.norm(t)
            s = 1.0 if float((eq.w * t) @ (eq.w * du)) >= 0.0 else -1.0
            k = s * c / nt if nt > 0 else 0.0
            ends.append((k * t, k * e["Kt"]))
        (Ta, KTa), (Tb, KTb) = ends
        return hermite_work(a["F"], b["F"], du, Ta, Tb, KTa, KTb)

    def _exceeded(self, eq, axial, shear, over):
        ratio = np.maximum(np.abs(axial), shear) / self.limit
        e = int(np.argmax(ratio))
        if self.worst is None or ratio[e] > self.worst[0]:
            kind = "axial" if abs(axial[e]) >= shear[e] else "shear"
            self.worst = (float(ratio[e]), f"{kind} strain {max(abs(axial[e]), shear[e]):.3g} beyond the strain "
                                           f"limit {self.limit[e]:g} of element {e} (yarn {eq.frame.yarn[e]}) at "
                                           f"load factor {eq.lam:.6g}")
        if self.first_exceed is None:
            self.first_exceed = (eq.lam, int(over.sum()))

    def finish(self):
        """The ledger check (flagged beyond 1 %); warn once (StrainWarning and the log) if any state
        went beyond a strain limit."""
        if self.rows and self.status is Status.OK:
            r = self.rows
            check = ledger_check([x["external_work"] for x in r], np.zeros(len(r)),
                                 [x["stabilization_energy"] for x in r], [x["energy_balance"] for x in r],
                                 [x["load_factor"] for x in r], driven=self.driven, limit=CHECK_LIMIT,
                                 floor=self.floor)
            snaps = [x[1] for x in self.events if x[0] == "snap"]
            if check and snaps:
                check = (f"snap-through at load factor {', '.join(f'{v:.6g}' for v in snaps)} (a limit point: the "
                         f"state jumped to the stable branch at the same load): {check}")
            if check:
                self.flag(check)
        if self.worst is None or self.warned:
            return
        self.warned = True
        msg = (f"the co-rotational beam is a small-strain element: {self.worst[1]} (largest excess; the first state "
               f"beyond a limit is at load factor {self.first_exceed[0]:.6g}); the answer is outside the elastic "
               "range it models")
        log.warning(msg)
        warnings.warn(msg, StrainWarning, stacklevel=3)

    def flag(self, detail: str):
        """Mark the path "flagged" (complete, but a check failed), adding ``detail``."""
        self.status = Status.FLAGGED
        self.detail = f"{self.detail}; {detail}" if self.detail else detail
        log.warning("solve_nonlinear: %s", detail)

    def spent(self, eq):
        msg = (f"steps spent: arc-length increments ended at load factor {eq.lam:.6g} before reaching 1 "
               "(raise steps or arc_length)")
        self.flag(msg)
        warnings.warn(msg, RuntimeWarning, stacklevel=4)

    def critical_load_factor(self) -> float:
        lam = [x[1] for x in self.events if x[0] in ("bifurcation", "limit")]
        return lam[0] if lam else float("nan")

    def dataset(self, attrs: dict) -> xr.Dataset:
        n = len(self.rows)
        data = {}
        for name, (units, long_name) in VARIABLES.items():
            vals = np.array([r[name] for r in self.rows]) if n else np.zeros(0)
            data[name] = ("step", vals, {"units": units, "long_name": long_name})
        coords = {"step": ("step", np.arange(1, n + 1), {"units": "1", "long_name": "converged state along the path"})}
        if self.nodes.size:
            coords.update(node=("node", self.nodes, {"units": "1", "long_name": "monitored node"}),
                          dof=("dof", list(DOFS), {"units": "1", "long_name": "degree of freedom"}))
            u = np.array([t[0] for t in self.track]).reshape(n, len(self.nodes), 6)
            f = np.array([t[1] for t in self.track]).reshape(n, len(self.nodes), 6)
            data["u"] = (("step", "node", "dof"), u, {
                "units": "mm (ux, uy, uz), rad (rx, ry, rz)",
                "long_name": "displacement of monitored nodes; rotations are accumulated spins (the angle about a "
                             "fixed axis, beyond pi too)"})
            data["force"] = (("step", "node", "dof"), f, {
                "units": "N (ux, uy, uz), N mm (rx, ry, rz)",
                "long_name": "external force on monitored nodes: loads plus support reactions (= internal force)"})
        ds = xr.Dataset(data, coords=coords)
        check = "ok: strains within the elastic limits" if self.worst is None else (
            "strain beyond the elastic limit: " + self.worst[1])
        kinds = {k: [x[1] for x in self.events if x[0] == k] for k in ("bifurcation", "limit", "snap")}
        ds.attrs.update({"control": self.control, "steps": self.steps, "step_cuts": self.cuts,
                         "status": self.status.value, "check": check,
                         "critical_load_factor": self.critical_load_factor(),
                         "bifurcation_load_factors": np.array(kinds["bifurcation"], dtype=float),
                         "limit_load_factors": np.array(kinds["limit"], dtype=float),
                         "snap_load_factors": np.array(kinds["snap"], dtype=float),
                         "branch_switches": np.array(self.switches, dtype=float).reshape(-1),
                         "branch_switches_note": "pairs (load factor of the critical state, perturbation along the "
                                                 "critical mode in weighted mm) of every switch to a secondary branch",
                         "energy_balance_note": "external work by Hermite steps (fourth order in the step)"})
        if self.status is not Status.OK:
            ds.attrs["status_detail"] = self.detail
        ds.attrs.update(attrs)
        return ds
