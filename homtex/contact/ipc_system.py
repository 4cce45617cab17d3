"""Contact setup, assembly, evaluation and energy bookkeeping of
:class:`~homtex.contact.incremental.IncrementalSolver` (a mixin: the solver's state lives there).

The free-DOF system is :class:`~homtex.analysis.tangent.FreeSystem` with the node pairs of
active contacts added to its pattern (it only grows; a contact block outside it rebuilds it),
the element tangents of :class:`~homtex.analysis.corotational.Corotational` (symmetric part),
the contact and friction blocks on the translations, and the pseudo-transient term M / delta on
its diagonal. The ledger accumulates the external work (trapezoidal sum of the forces on
prescribed DOFs, plates and loads times their motion), the pre-strain work, the friction
dissipation and the stabilisation, and holds the strain and contact energy changes.
"""

from __future__ import annotations

import contextlib

import numba
import numpy as np
import scipy.linalg as sla
import scipy.sparse.linalg as spla

from ..analysis.energy import balance, energy_floor
from ..analysis.tangent import FreeSystem
from ..fem.corotational_system import element_matvec_serial, spin_between
from ..linalg.solvers import blas_single_thread
from .ccd import pair_step_bound, plate_step_bound
from .friction import friction_potential
from .ipc_scene import ContactScene, friction_setup
from .lattice import LatticeScene, image_motion
from .lattice_system import BorderedSystem
from .potential import Enforcement, pair_gaps

__all__ = ["SystemMixin", "lag_change", "serial_numba"]


class _StepFailed(Exception):
    """A step that did not converge (the solver restores its state and raises SolverError)."""


@contextlib.contextmanager
def serial_numba(small: bool):
    """numba and BLAS on one thread for small frames (a parallel launch costs more than the work
    there). BLAS too: its threads, woken for the vector products of every Newton iteration, kept
    the second core busy: the 43 mm seam cell sewn and pressed to 70 % (2416 elements, idle 2-core
    machine, 2026-11-29) took 688 s of wall and 1308 s of CPU, with one BLAS thread 677 s and 677 s
    (the same stresses): a core freed for a second process, 1.6 % of wall time."""
    if not small:
        yield
        return
    old = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        with blas_single_thread():
            yield
    finally:
        numba.set_num_threads(old)



class SystemMixin:
    """Pattern, assembly, evaluation and ledger of the large-motion step solver."""

    # ------------------------------------------------------------------ contact setup
    def _contact_setup(self, frame, contact, friction_spec, initial) -> None:
        """Enforcements (barrier, or barrier at the cores under compressible shells), friction
        slip, search margins and the contact scene."""
        r = frame.contact_radius
        comp = contact.compression
        h = 0.0
        if comp is not None:
            comp.check_radius(float(r.min()))
            h = comp.shell
        ghat = contact.barrier_gap * float(r.min() - h)
        kappa = contact.barrier_stiffness or float(np.mean(frame.EA / frame.length))
        sag = contact.parallel_sagitta
        enf = plate_enf = Enforcement("barrier", ghat=ghat, kappa=kappa, parallel_sagitta=sag)
        if comp is not None:
            enf = Enforcement("shell", ghat=ghat, kappa=kappa, parallel_sagitta=sag, **comp.pair_params())
            plate_enf = Enforcement("shell", ghat=ghat, kappa=kappa, **comp.plate_params())
        eps_v = contact.friction_slip if contact.friction_slip is not None else 1e-3 * float(r.min())
        self.ghat, self.kappa, self.eps_v = ghat, kappa, eps_v
        margin = contact.margin if contact.margin is not None else max(float(r.max()), 20.0 * ghat)
        margin = max(margin, 2.0 * ghat, enf.cutoff + 2.0 * ghat)
        args = (frame, self.plates, enf, plate_enf, friction_setup(frame, contact, friction_spec), margin)
        kw = {"touch": None if initial is None else initial.touch, "core": h}
        self.scene = LatticeScene(*args, driver=self.lat, **kw) if self.lat is not None else ContactScene(*args, **kw)
        # the widest search: a node moves at most half of it per iteration
        self.max_margin = max(self.scene.margin, 4.0 * float(r.max()))

    # ------------------------------------------------------------------ pattern and assembly
    def _pattern(self, nodes=None) -> None:
        """(Re)build the free-DOF pattern with the node pairs of stencils ``nodes`` (c, S) added
        to those it has (it only grows: contacts that were active once are likely to return)."""
        c = self.scene.couplings(nodes)
        N = self.N
        have = self._coupled[:, 0] * N + self._coupled[:, 1]
        new = c[:, 0] * N + c[:, 1]
        if self.sys is not None and np.isin(new, have).all():
            return
        reach = self.s.pattern_reach
        st = self.scene.stencil
        if reach > 0 and self.sys is not None and len(st):
            # a rebuild takes the pairs about to touch along (NonlinearSettings.pattern_reach)
            gap = pair_gaps(self._xc(self.positions), st)
            near = self._real(st.nodes[gap < reach * self.ghat])
            c2 = self.scene.couplings(near)
            new = np.union1d(new, c2[:, 0] * N + c2[:, 1])
        allk = np.union1d(have, new)
        self._coupled = np.column_stack([allk // N, allk % N])
        if self.lat is None:
            self.sys = FreeSystem(self.frame, self.mask, "ldl", couplings=self._coupled)
        else:                   # the lattice DOFs border the nodes' system
            inner = self.mask.reshape(N, 6).copy()
            inner[self.lat.rows] = True
            self.sys = BorderedSystem(FreeSystem(self.frame, inner.ravel(), "ldl", couplings=self._coupled), self.lat,
                                      self.free, self.frame.elements)
        pn = self.scene.plate_block_nodes(np.arange(self.n * self.P))
        self.plate_slots = self.sys.block_slots(pn) if len(pn) else np.zeros((0, 6, 6), dtype=np.int32)
        self.info.patterns += 1

    def _slots(self, nodes) -> np.ndarray:
        """Slots of blocks over ``nodes`` (na, S), the pattern grown first where they need it."""
        sl = self.sys.block_slots(nodes, strict=False)
        if sl is None:
            self._pattern(nodes)
            sl = self.sys.block_slots(nodes)
        return sl

    def _search(self, x, margin=None) -> None:
        self.scene.search(x, margin)
        self.info.searches += 1

    # ------------------------------------------------------------------ potential
    def _evaluate(self, x_start, lag, hessian: bool, project: bool = False, eps_hessian: float = 0.0) -> dict:
        """Forces, energies and (hessian) blocks at the current state; gradient g (N, 6).
        ``project``: contact and friction blocks projected to PSD (else their exact Hessians).
        ``eps_hessian``: friction blocks for this saturation slip if it is larger than the
        model's (a predictor: friction is mobilised over the slip of the step, not eps_v)."""
        s = self.prestrain_scale
        fint = self.cor.evaluate_tangent(s) if hessian else self.cor.evaluate(s)
        x = self.positions
        xc = self._xc(x)
        z = self.plates.z
        n, P = self.n, self.P
        pc = self.scene.pairs(xc, hessian, project=project)
        pl = self.scene.plate_terms(x, z, hessian)
        g = np.zeros((self.N, 6))
        g[:n] = fint
        g[:n, :3] += pl["grad"]
        self._fold(pc.grad, g)
        g[n:n + P, 2] = pl["grad_plate"]
        if self.lat is not None:
            g[self.lat.rows, :3] += self.lat.element_grad(self.cor.fe)
            x_start = self._xc(x_start, self._p_start)
        ev = {"U": float(self.cor.energy.sum()), "B": pc.energy + pl["energy"], "pairs": pc, "plates": pl,
              "D": 0.0, "fric": [], "fint": fint, "terms": []}
        for t in self.terms:        # potentials scaled with the pre-strain: booked with the strain energy
            e, gt, nodes, H = t.evaluate(x, s, hessian)
            ev["U"] += e
            g[:self.n, :3] += gt
            fint = fint + np.pad(gt, ((0, 0), (0, 3)))
            if hessian:
                ev["terms"].append((nodes, H))
        for lg in lag:
            if lg is None or not len(lg):
                continue
            fr = friction_potential(lg, xc, x_start, self.eps_v, hessian=hessian, project=project)
            if hessian and eps_hessian > self.eps_v:
                fr.hess = friction_potential(lg, xc, x_start, eps_hessian, hessian=True, project=project).hess
            ev["D"] += fr.energy
            ev["fric"].append((lg, fr))
            self._fold(fr.grad, g)
        ev["g_contact"] = g[:, :3].copy()
        ev["g_contact"][:n] -= fint[:, :3]
        ev["fint"] = fint
        g[:n] -= self.applied_loads()
        g[n:n + P, 2] -= self.plate_force
        if self.lat is not None:
            g[self.lat.rows, :3] -= self._lattice_loads()
        ev["g"] = g
        ev["Pi"] = ev["U"] + ev["B"] + ev["D"]
        return ev

    def _assemble(self, ev) -> None:
        """Beam tangent (symmetric part) plus the contact and friction blocks into the free system."""
        sys = self.sys
        sys.assemble(self.cor.Ke)
        if self.M is None:
            self.M = self._lumped()
        pc, pl = ev["pairs"], ev["plates"]
        # slots first: a block outside the pattern rebuilds it (and the beam part with it)
        slots = [self._slots(self._real(pc.hess_nodes)) if pc.n_active else None]
        fric = ev["fric"]
        slots += [self._friction_slots(lg) for lg, _ in fric]
        slots += [self._slots(nodes) for nodes, _ in ev.get("terms", ())]
        if self.sys is not sys:
            sys = self.sys
            sys.assemble(self.cor.Ke)
        if pc.n_active:
            sys.add_blocks(pc.hess, slots[0])
            self._lattice_blocks(pc.hess, pc.hess_nodes)
        if len(pl["active"]):
            sys.add_blocks(pl["blocks"], self.plate_slots[pl["active"]])
        for (lg, fr), sl in zip(fric, slots[1:]):
            sys.add_blocks(fr.hess, sl)
            self._lattice_blocks(fr.hess, lg.nodes)
        for (_, H), sl in zip(ev.get("terms", ()), slots[1 + len(fric):]):
            sys.add_blocks(H, sl)
        self._hmax = float(np.abs(sys.diagonal()).max(initial=0.0))

    def _friction_slots(self, lg):
        cached = getattr(lg, "slots", None)
        if cached is None or cached[0] is not self.sys:
            sl = self._slots(self._real(lg.nodes))
            lg.slots = (self.sys, sl)
        return lg.slots[1]

    def _hess_times(self, ev, d) -> np.ndarray:
        """(N, 6) H d for a prescribed increment d (N, 6): beam tangent and contact blocks."""
        out = np.zeros((self.N, 6))
        if np.any(d[:self.n]):
            p = self.cor.asm.pattern
            tmp = np.empty((self.n, 6))
            element_matvec_serial(p.node_ptr, p.inc_elem, p.inc_end, self.frame.elements, self.cor.Ke,
                                  np.ascontiguousarray(d[:self.n]), tmp)
            out[:self.n] = tmp
        if self.lat is not None:
            self.lat.element_hess_times(self.cor.Ke, d, out, self.frame.elements)
        pc, pl = ev["pairs"], ev["plates"]
        real = [(H, nodes) for nodes, H in ev.get("terms", ())]   # thread terms: over real nodes
        if len(pl["active"]):           # plates: over (node, plate row) of the DOF arrays
            real.append((pl["blocks"], self.scene.plate_block_nodes(pl["active"])))
        for H, nodes in real:
            v = d[:, :3][nodes].reshape(len(nodes), -1)
            hv = np.einsum("rij,rj->ri", H, v).reshape(len(nodes), -1, 3)
            np.add.at(out[:, :3], nodes.ravel(), hv.reshape(-1, 3))
        blocks = [(pc.hess, pc.hess_nodes)] if pc.n_active else []
        blocks += [(fr.hess, lg.nodes) for lg, fr in ev["fric"] if len(lg)]
        if blocks:                      # pairs and friction: over the contact positions
            dc = self._disp_c(d)
            oc = np.zeros_like(dc)
            for H, nodes in blocks:
                v = dc[nodes].reshape(len(nodes), -1)
                hv = np.einsum("rij,rj->ri", H, v).reshape(len(nodes), -1, 3)
                np.add.at(oc, nodes.ravel(), hv.reshape(-1, 3))
            self._fold(oc, out)
        return out

    def _lumped(self) -> np.ndarray:
        """M (nf,): |diagonal| of the beam tangent on the free DOFs (plates: the mean of the
        translations), floored; frozen for the step."""
        d = np.abs(self.sys.diagonal())
        dof = self.free
        node = dof // 6
        trans = (node < self.n) & (dof % 6 < 3)
        mean_t = float(d[trans].mean()) if trans.any() else 1.0
        d = np.where(node >= self.n, mean_t, d)
        return np.maximum(d, 1e-9 * float(d.max(initial=1.0)))

    def _factor(self, it, shrink: bool = True) -> bool:
        """Factor H + M / delta; ``shrink``: shrink delta until no negative pivot remains (else
        return whether the factor is positive definite)."""
        save = getattr(self.sys, "save", None)
        base = save() if save is not None else self.sys.A.data.copy()
        for _ in range(40):
            self._load(base)
            self.sys.add_diagonal(self.M / self.delta)
            self.sys.factor(inertia=True)
            if self.sys.negative == 0:
                return True
            if not shrink:
                self._load(base)
                return False
            self.info.extra["indefinite"] = True        # the beams (not the contacts) buckle here
            self.delta = max(self.delta / 4.0, 1e-12)
        raise _StepFailed(f"the tangent stays indefinite at iteration {it} (delta {self.delta:.2e})")

    # ------------------------------------------------------------------ critical modes
    def critical_mode(self) -> tuple[float, np.ndarray]:
        """(lowest eigenvalue of the diagonally scaled Hessian of beams and contacts on the free DOFs
        at the current state, its mode (N, 6) with unit largest translation): the direction a
        buckling state leaves in (friction left out: its Hessian is positive semi-definite)."""
        ev = self._evaluate(self.positions, [], hessian=True)
        self._assemble(ev)
        S = self.sys.symmetric()
        d = np.abs(S.diagonal())
        d = np.where(d > 0, d, max(float(d.max(initial=1.0)), 1.0))
        sc = 1.0 / np.sqrt(d)
        Ss = S.multiply(sc[:, None]).multiply(sc[None, :]).tocsc()
        if Ss.shape[0] <= 400:
            with blas_single_thread():
                mu, V = sla.eigh(Ss.toarray(), subset_by_index=[0, 0])
            mu, v = float(mu[0]), V[:, 0]
        else:
            try:
                mu, V = spla.eigsh(Ss, k=1, sigma=-1e-6, which="LM", tol=1e-8)
            except RuntimeError:
                mu, V = spla.eigsh(Ss, k=1, which="SA", tol=1e-6)
            mu, v = float(mu[0]), V[:, 0]
        mode = np.zeros(self.N * 6)
        mode[self.free] = v * sc
        mode = mode.reshape(self.N, 6)
        big = float(np.abs(mode[:, :3]).max(initial=0.0))
        return mu, mode / big if big > 0 else mode

    def perturb(self, mode: np.ndarray, amp: float) -> float:
        """Move the state by amp x mode (N, 6; mm, rad), cut by the collision check so that no yarn
        passes through another or a plate; returns the amplitude applied (mm)."""
        x = self.positions
        d = amp * mode
        dx, dz = d[:self.n, :3], d[self.n:self.n + self.P, 2]
        dxc = self._disp_c(d)
        reach = float(np.sqrt(np.einsum("ij,ij->i", dxc, dxc)).max(initial=0.0))
        if self.lat is not None:            # the neighbouring cells' copies move with the lattice too
            reach = max(reach, float(np.sqrt(np.einsum("ij,ij->i", dx, dx)).max(initial=0.0))
                        + image_motion(d[self.lat.rows, :3]))
        if not self.scene.covers(x, reach):
            self._search(x, min(max(self.scene.margin, 2.2 * reach + 2.0 * self.ghat), self.max_margin))
        a = 1.0
        if len(self.scene.stencil):
            dxc = self._disp_c(d)           # (a search may have added virtual nodes)
            a = min(a, pair_step_bound(self._xc(x), dxc, self.scene.stencil, eta=self.s.eta))
        if self.P:
            pn, pi = self.scene.plate_nodes, self.scene.plate_index
            a = min(a, plate_step_bound(x, dx, pn, self.scene.node_r[pn], self.plates.origins(), self.plates.normals(),
                                        plate=pi, plate_motion=np.column_stack([np.zeros((self.P, 2)), dz]),
                                        eta=self.s.eta))
        self._apply(a, d)
        return a * amp

    def _load(self, base) -> None:
        if hasattr(self.sys, "load"):
            self.sys.load(base)
        else:
            self.sys.A.data[:] = base

    # ------------------------------------------------------------------ energy ledger
    def _start_ledger(self) -> None:
        self.energy_floor = energy_floor(self.frame)
        ev = self._evaluate(self.positions, [], hessian=False)
        self._ev0 = {"U": ev["U"], "B": ev["B"]}
        self.ledger = {"external_work": 0.0, "prestrain_work": 0.0, "dissipation": 0.0, "stabilization": 0.0,
                       "U0": ev["U"], "B0": ev["B"], "strain_energy": 0.0, "contact_energy": 0.0}
        self._react = self._reactions(ev)
        self._prev = self.snapshot()
        self._dUds = self._prestrain_rate()

    def _reactions(self, ev) -> np.ndarray:
        """(N, 6) forces the surroundings apply on prescribed DOFs and loaded DOFs (N, N mm)."""
        f = self.applied_loads()
        g = ev["g"].copy()
        n, P = self.n, self.P
        g[:n] += f
        g[n:n + P, 2] += self.plate_force
        if self.lat is not None:
            g[self.lat.rows, :3] += self._lattice_loads()
        r = np.where(self.mask.reshape(self.N, 6), g, 0.0)
        r[:n] += f
        r[n:n + P, 2] += self.plate_force
        if self.lat is not None:
            r[self.lat.rows, :3] += self._lattice_loads()
        return r

    def _prestrain_rate(self) -> float:
        f = self.frame
        x = self.positions
        return float(np.sum(self.cor.forces[:, 6] * f.length * f.prestrain)) + sum(t.rate(x) for t in self.terms)

    def _account(self, info, snap) -> None:
        ev = info.extra["ev"]
        react = self._reactions(ev)
        du = np.zeros((self.N, 6))
        du[:self.n, :3] = self.cor.ut - snap[0]
        spin_between(self.cor.Q, snap[1], du[:self.n, 3:])
        du[self.n:self.n + self.P, 2] = self.plates.z - snap[2]
        if self.lat is not None:
            du[self.lat.rows, :3] = self.lat.periods - snap[9]
        L = self.ledger
        L["external_work"] += 0.5 * float(np.sum((self._react + react) * du))
        rate = self._prestrain_rate()
        L["prestrain_work"] += 0.5 * (self._dUds + rate) * (self.prestrain_scale - snap[4])
        L["dissipation"] += info.dissipation
        L["stabilization"] += info.stabilization
        L["strain_energy"] = ev["U"] - L["U0"]
        L["contact_energy"] = ev["B"] - L["B0"]
        self._react, self._dUds = react, rate
        info.extra["reactions"] = react

    def balance(self) -> float:
        """The relative energy balance of the path so far (:func:`homtex.analysis.energy.balance`)."""
        L = self.ledger
        return balance(L["external_work"], L["prestrain_work"], L["strain_energy"], L["contact_energy"],
                       L["dissipation"], L["stabilization"], floor=self.energy_floor)



def lag_change(old, new, n) -> float:
    """Relative change of the lagged normal force per node between two lags (pairs, plates)."""
    def per_node(lag):
        out = np.zeros(n)
        for lg in lag:
            if lg is None or not len(lg):
                continue
            w = np.abs(lg.lam[:, :, None] * lg.coef).sum(axis=1)         # (rows, S)
            np.add.at(out, lg.nodes.ravel(), w.ravel())
        return out
    a, b = per_node(old), per_node(new)
    scale = max(float(np.abs(b).max(initial=0.0)), 1e-300)
    return float(np.abs(a - b).max(initial=0.0) / scale)


