"""What a path-following solve records at every converged state, and the strain-range monitor.

Per state: load factor, stability (negative eigenvalues of the tangent), Newton iterations and
residual, the strain-energy split summed over the elements (axial, torsion, bending about both
section axes, shear; N mm), the external work (trapezoidal accumulation of f . du along the path,
reactions included, moments against spins; N mm) and the relative energy balance, the largest
axial, shear and bending strains and the largest deformational rotation. The element is a
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
    "external_work": ("N mm", "work of loads and reactions (trapezoidal sum of f . du along the path)"),
    "energy_balance": ("1", "(external work - strain energy) / max(|external work|, strain energy)"),
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
        self.cuts = 0
        self.initial = None
        self.status = "ok"
        self.warned = False
        self.first_exceed = None
        self.worst = None
        self.changes = []           # rows where the inertia changed along an arc-length path

    def start(self, eq):
        """The initial state (lambda = 0, refreshed): reference energy, force and state."""
        self.initial = eq.snapshot()
        self.U0 = float(eq.cor.energy.sum())
        self.work = 0.0
        self.f_prev = eq.fint.copy()
        self.snap_prev = self.initial
        self.u_acc = np.zeros(6 * eq.n)
        self.track = []
        self.limit = np.asarray(eq.frame.strain_limit, dtype=float)

    def event(self, kind: str, lam: float, negative: int):
        self.events.append((kind, float(lam), int(negative)))

    def record(self, eq, iterations: int, residual: float, snap, arc: bool = False):
        """Record the current converged state (the step started from the last recorded one)."""
        du = eq.increment_since(self.snap_prev)
        self.work += 0.5 * float((self.f_prev + eq.fint) @ du)
        self.u_acc += du
        if self.nodes.size:
            self.track.append((self.u_acc.reshape(-1, 6)[self.nodes].copy(), eq.fint.reshape(-1, 6)[self.nodes].copy()))
        self.f_prev = eq.fint.copy()
        self.snap_prev = eq.snapshot()
        U = eq.cor.energy.sum(axis=0)
        dU = float(U.sum()) - self.U0
        scale = max(abs(self.work), abs(dU), 1e-300)
        axial, shear, bend = eq.cor.strains()
        over = (np.abs(axial) > self.limit) | (shear > self.limit)
        neg = -1 if eq.negative is None else int(eq.negative)
        if arc and self.rows and neg >= 0 and self.rows[-1]["negative_eigenvalues"] >= 0 and \
                neg != self.rows[-1]["negative_eigenvalues"]:
            self.changes.append(len(self.rows))          # classified in _classified()
        row = {"load_factor": eq.lam, "stable": neg == 0, "negative_eigenvalues": neg, "iterations": iterations,
               "residual": residual, **dict(zip(ENERGY_NAMES, (float(v) for v in U))), "strain_energy": dU,
               "external_work": self.work, "energy_balance": (self.work - dU) / scale,
               "max_axial_strain": float(np.abs(axial).max()), "max_shear_strain": float(shear.max()),
               "max_bending_strain": float(bend.max()), "strain_exceeded": bool(over.any()),
               "max_deformational_rotation": eq.cor.max_deformational_rotation()}
        self.rows.append(row)
        if over.any():
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
        """Warn once (StrainWarning and the log) if any state went beyond a strain limit."""
        if self.worst is None or self.warned:
            return
        self.warned = True
        msg = (f"the co-rotational beam is a small-strain element: {self.worst[1]} (largest excess; the first state "
               f"beyond a limit is at load factor {self.first_exceed[0]:.6g}); the answer is outside the elastic "
               "range it models")
        log.warning(msg)
        warnings.warn(msg, StrainWarning, stacklevel=3)

    def spent(self, eq):
        self.status = (f"steps spent: arc-length increments ended at load factor {eq.lam:.6g} before reaching 1 "
                       "(raise steps or arc_length)")
        log.warning(self.status)
        warnings.warn(self.status, RuntimeWarning, stacklevel=4)

    def _classified(self):
        """Events: those recorded by the controls plus the inertia changes of an arc-length path,
        a limit point where the load factor has an extremum next to the change (its value refined
        by a parabola through three states), else a bifurcation."""
        lam = np.array([r["load_factor"] for r in self.rows])
        out = list(self.events)
        for i in self.changes:
            lo, hi = max(i - 2, 0), min(i + 2, len(lam) - 1)
            d = np.diff(lam[lo:hi + 1])
            turn = np.flatnonzero(d[:-1] * d[1:] < 0)
            neg = self.rows[i]["negative_eigenvalues"]
            if turn.size:
                k = lo + int(turn[0]) + 1
                a, b, c = lam[k - 1:k + 2]
                den = 2 * b - a - c
                out.append(("limit", float(b + (a - c) ** 2 / (8 * den)) if den != 0 else float(b), neg))
            else:
                out.append(("bifurcation", float(0.5 * (lam[i - 1] + lam[i])), neg))
        return out

    def critical_load_factor(self) -> float:
        lam = [x[1] for x in self._classified() if x[0] in ("bifurcation", "limit")]
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
        events = self._classified()
        kinds = {k: [x[1] for x in events if x[0] == k] for k in ("bifurcation", "limit")}
        ds.attrs.update({"control": self.control, "steps": self.steps, "step_cuts": self.cuts,
                         "status": self.status, "check": check,
                         "critical_load_factor": self.critical_load_factor(),
                         "bifurcation_load_factors": np.array(kinds["bifurcation"], dtype=float),
                         "limit_load_factors": np.array(kinds["limit"], dtype=float),
                         "energy_balance_note": "trapezoidal external work: O(step^2) truncation error"})
        ds.attrs.update(attrs)
        return ds
