"""Contact solve of a linear frame: candidates, constraint rows, re-detection, results.

For a linear frame (stiffness K, loads f) and candidate constraints g + C u >= 0 (see
:mod:`homtex.contact.constraints`) the solution minimises 1/2 u K u - f u subject to the
constraints: a convex quadratic programme with a unique answer when K is positive definite
on the admissible motions. Its active set is found by the strategies of
:mod:`homtex.contact.activeset`; new contacts that the deformed state shows are added and the
step re-solved (:meth:`ContactSolver.solve`).

The load the frame carries is a state of the solver: applied loads, the pre-strain at its
current scale (a sewing ramp raises it step by step) and the axial stiffness of each element
(a slack thread carries none). The stiffness, the load vector and the reported element forces
all read that state, so an intermediate state reports forces that match its load.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.sparse as sp

from ..analysis.static import check_finite, element_state, prestrain_load
from ..config import option
from ..errors import InputError, SolverError
from ..fem.assembly import Assembler
from ..linalg.nullspace import rigid_body_modes
from ..model.frame import Frame
from ..model.results import ENERGY_KEYS, StaticResult
from ..model.scene import Scene
from .activeset import ActiveSets
from .broad import BroadPhase, exclusion_lists
from .constraints import ContactSet, build_rows, dedupe_pairs, pair_keys, plate_keys, point_keys
from .linsys import LinearSystems
from .options import Contact

__all__ = ["ContactSolver", "solve_contact"]


class ContactSolver(ActiveSets, LinearSystems):
    """A frame with supports, loads, plates and contact options; solves for the contact state.

    The stiffness is assembled once; :meth:`solve` may be called repeatedly (plate motions
    changed with :meth:`set_plate`, the pre-strain scale with :meth:`set_prestrain_scale`,
    linearisation point ``u_ref`` moved), as ``compress`` does. Plate p is an extra node
    n + p whose only free DOF (force control) is uz.

    ``solver`` and ``tol`` default to the options ``static_solver`` and ``tol``.
    """

    def __init__(self, frame: Frame, fixed=None, loads=None, contact: Contact | None = None, *,
                 plates=(), solver: str | None = None, tol: float | None = None, maxiter: int | None = None,
                 assembler: Assembler | None = None):
        if not isinstance(frame, Frame):
            raise InputError(f"frame must be a homtex.Frame, got {type(frame).__name__}")
        if contact is None:
            contact = Contact()
        if not isinstance(contact, Contact):
            raise InputError(f"contact must be a homtex.Contact, got {type(contact).__name__}")
        contact.require_frictionless()
        solver = option("static_solver", solver)
        if solver not in ("amg", "direct", "cg"):
            raise InputError(f"solver must be one of ('amg', 'direct', 'cg'), got {solver!r}")
        self.scene = Scene.build(frame, fixed, loads, plates)
        self.frame, self.contact, self.plates = frame, contact, self.scene.plates
        self.solver, self.tol, self.maxiter = solver, float(option("tol", tol)), maxiter
        n = frame.n_nodes
        P = len(self.plates)
        self.n, self.P, self.N = n, P, n + P
        self.frame_mask = self.scene.mask
        self.mask = np.concatenate([self.scene.mask, np.ones(6 * P, dtype=bool)])
        self.up = np.concatenate([self.scene.values, np.zeros(6 * P)])
        self.f_loads = self.scene.loads
        self.prestrain_scale = 1.0
        self.axial_scale = None
        self.f = np.concatenate([self.f_loads + prestrain_load(frame), np.zeros(6 * P)])
        asm = assembler or Assembler(frame)
        self.assembler = asm
        self.set_stiffness(asm.stiffness())
        d = self.K.diagonal().reshape(n, 6)[:, :3]
        self.k_scale = float(d.mean())
        penalty = contact.penalty if contact.penalty is not None else option("contact_penalty")
        self.k = float(penalty) if penalty is not None else self.k_scale
        r = frame.contact_radius
        self.r_mean, self.r_min, self.r_max = float(r.mean()), float(r.min()), float(r.max())
        self.margin = self.r_max if contact.margin is None else float(contact.margin)
        if contact.exclude_hops is None:
            hops = max(2, int(math.ceil((2 * self.r_max + self.margin) / float(frame.length.min()))) + 1)
            hops = min(hops, 20)
        else:
            hops = int(contact.exclude_hops)
        self.hops = hops
        self.broad = BroadPhase(frame.elements, r, frame.periods, frame.images, exclusion_lists(frame, hops))
        self.node_r = frame.node_radius
        self.plate_z0 = np.array([float(p.z) for p in self.plates])
        for i, p in enumerate(self.plates):
            self.set_plate(i, displacement=p.displacement, force=p.force)
        xy = frame.nodes.mean(axis=0)
        coords = np.vstack([frame.nodes, np.column_stack([np.full(P, xy[0]), np.full(P, xy[1]), self.plate_z0])])
        self.B = rigid_body_modes(coords)
        self.gtol = contact.gap_tol * self.r_mean
        # re-detection: an uncovered pair counts as new contact when it overlaps by more than this
        # (chords of bent yarns meeting at a node overlap slightly without a real contact)
        self.dtol = max(contact.detect_tol * self.r_min, self.gtol)
        self._ml = None
        self._ml_sig = None
        self._base_iters = None
        self.stats = _new_stats()
        self._initial_overlaps()

    def _initial_overlaps(self):
        """Gap offsets (by pair key) of yarn pairs that overlap in the undeformed frame ("touch")."""
        frame, r = self.frame, self.frame.contact_radius
        self.offset_keys = np.zeros(0, dtype=np.int64)
        self.offset_vals = np.zeros(0)
        if self.contact.initial_overlap == "touch":
            pr = self.broad.pairs(frame.nodes, 0.0)
            keep = dedupe_pairs(frame, pr["a"], pr["b"], pr["image"], pr["s"], pr["t"])
            a, b, im, dist = pr["a"][keep], pr["b"][keep], pr["image"][keep], pr["dist"][keep]
            g0 = dist - (r[a] + r[b])
            ov = g0 < 0
            keys = pair_keys(a[ov], b[ov], im[ov], frame.n_elements)
            order = np.argsort(keys)
            self.offset_keys, self.offset_vals = keys[order], -g0[ov][order]
        self.initial_overlaps = len(self.offset_keys)
        self.initial_overlap_max = float(self.offset_vals.max(initial=0.0))

    # ------------------------------------------------------------------ load state
    def set_stiffness(self, K):
        """Replace the frame's stiffness (e.g. the co-rotational tangent; same DOFs). The contact
        penalty keeps its scale from the first stiffness; a reused AMG hierarchy is dropped."""
        K = K.tocsr()
        self.K = K
        self.K_ext = sp.block_diag([K, sp.csr_matrix((6 * self.P, 6 * self.P))], format="csr") if self.P else K.copy()
        self._ml = None

    @property
    def prestrain(self) -> np.ndarray:
        """(m,) the pre-strain the elements carry now (the frame's, times the current scale)."""
        return self.prestrain_scale * self.frame.prestrain

    def set_prestrain_scale(self, alpha: float) -> None:
        """Carry ``alpha`` x the frame's pre-strain from now on (load, stiffness state and the
        element forces of later results)."""
        self.prestrain_scale = float(alpha)
        self._update_frame_load()

    def set_axial_scale(self, scale) -> None:
        """Multiply each element's axial stiffness by ``scale`` (m,) (None: the frame's): a slack
        thread carries neither axial load nor its pre-strain. Reassembles the stiffness."""
        self.axial_scale = None if scale is None else np.asarray(scale, dtype=float)
        R, L, EA, GJ, EIy, EIz, kGA = self.assembler.element_arrays()
        if self.axial_scale is not None:
            EA = EA * self.axial_scale
        self.set_stiffness(self.assembler.stiffness((R, L, EA, GJ, EIy, EIz, kGA)))
        self._update_frame_load()

    def set_frame_load(self, f_frame) -> None:
        """Replace the load on the frame's DOFs (6n,), N, N mm (Newton steps load the frame with
        its out-of-balance force); plate loads are kept."""
        self.f[:6 * self.n] = np.asarray(f_frame, dtype=float)

    @property
    def plate_load(self) -> np.ndarray:
        """(6P,) loads on the plates' DOFs (force control), N."""
        return self.f[6 * self.n:].copy()

    def _update_frame_load(self):
        EA = None if self.axial_scale is None else self.frame.EA * self.axial_scale
        self.f[:6 * self.n] = self.f_loads + prestrain_load(self.frame, EA, self.prestrain)

    def set_plate(self, p: int, *, displacement=None, force=None):
        """Displacement control (mm along z) or force control (N pressing the plate on the yarns)."""
        pl = self.plates[p]
        i = 6 * (self.n + p) + 2
        if force is not None:
            pl.displacement, pl.force = None, float(force)      # in this order: a Plate checks every assignment
            self.mask[i] = False
            self.up[i] = 0.0
            self.f[i] = pl.normal * float(force)
        else:
            pl.force, pl.displacement = None, float(displacement or 0.0)
            self.mask[i] = True
            self.up[i] = pl.displacement
            self.f[i] = 0.0

    # ------------------------------------------------------------------ candidates
    def _offset(self, keys):
        """(len(keys),) gap offset of each candidate (initial overlap treated as touching), mm."""
        return _by_key(self.offset_keys, self.offset_vals, keys)

    def _candidates(self, x, plate_z, margin, plate_target=None):
        """Yarn pairs and node-plate pairs closer than ``margin`` at positions x (n, 3)."""
        pr = self.broad.pairs(x, margin)
        keep = dedupe_pairs(self.frame, pr["a"], pr["b"], pr["image"], pr["s"], pr["t"])
        pr = {key: v[keep] for key, v in pr.items()}
        pn, pi = [], []
        for p, pl in enumerate(self.plates):
            g = pl.normal * (x[:, 2] - plate_z[p]) - self.node_r
            if plate_target is not None:
                g = np.minimum(g, pl.normal * (x[:, 2] - plate_target[p]) - self.node_r)
            sel = np.flatnonzero(g < margin)
            pn.append(sel)
            pi.append(np.full(len(sel), p, dtype=np.int64))
        pn = np.concatenate(pn) if pn else np.zeros(0, dtype=np.int64)
        pi = np.concatenate(pi) if pi else np.zeros(0, dtype=np.int64)
        return pr["a"], pr["b"], pr["image"], pn, pi

    def _check_held(self, rows, active):
        el = self.frame.elements
        c = rows.n_yarn
        ay = np.flatnonzero(active[:c])
        ap = np.flatnonzero(active[c:])
        mask = self.frame_mask.copy()
        mask[6 * rows.pnode[ap] + 2] = True
        edges = np.column_stack([el[rows.ea[ay], 0], el[rows.eb[ay], 0]])
        self.scene.check_held(edges, rows.image[ay], mask=mask)
        for p, pl in enumerate(self.plates):
            if pl.force_controlled and not np.any(rows.pidx[ap] == p):
                raise SolverError(f"plate {p} ({pl.name or 'force-controlled'}, z = {pl.z}) is held by nothing: "
                                  "no active contact with the yarns (force control needs the plate to touch)")

    def _name(self, rows, q):
        c = rows.n_yarn
        if q < c:
            a, b = int(rows.ea[q]), int(rows.eb[q])
            y = self.frame.yarn
            img = f", image {rows.image[q].tolist()}" if rows.image.shape[1] else ""
            return f"yarn-yarn contact elements {a} (yarn {y[a]}) / {b} (yarn {y[b]}{img})"
        q -= c
        return f"yarn-plate contact node {int(rows.pnode[q])} / plate {int(rows.pidx[q])}"

    # ------------------------------------------------------------------ solve
    def solve(self, u_ref=None, warm_keys=None, warm_forces=None) -> StaticResult:
        """Contact equilibrium linearised about ``u_ref`` (N, 6) (default 0).

        ``warm_keys`` (contact keys active before) start the active set; ``warm_forces`` (same
        length) also start their multipliers (N): Newton steps near convergence move contacts by
        round-off, and a cold multiplier would then let a loaded contact open.

        Returns a :class:`~homtex.model.results.StaticResult` with ``.contacts`` and ``extra``
        (iterations, linear solves, timings, plate forces and displacements, contact energy).
        """
        cont = self.contact
        frame = self.frame
        n, N = self.n, self.N
        u_ref = np.zeros((N, 6)) if u_ref is None else np.asarray(u_ref, dtype=float).reshape(N, 6)
        x_ref = frame.nodes + u_ref[:n, :3]
        pz_ref = self.plate_z0 + u_ref[n:, 2]
        target = np.array([self.plate_z0[p] + (pl.displacement if pl.displacement is not None else u_ref[n + p, 2])
                           for p, pl in enumerate(self.plates)])
        cand = self._candidates(x_ref, pz_ref, self.margin, target)
        stats0 = dict(self.stats)
        iters = updates = 0
        x = u_ref.ravel().copy()
        x[self.mask] = self.up[self.mask]
        prev = None
        for rnd in range(cont.detect_rounds + 1):
            rows = build_rows(frame, x_ref, *cand, self.plates, pz_ref, self.node_r)
            rows.g = rows.g + self._offset(rows.keys)
            g = rows.g - rows.C @ u_ref.ravel()         # constraint g + C u >= 0 in total u
            self._rigid = self._rigid_rows(rows, g)
            active, lam = self._start_set(rows, prev, warm_keys, warm_forces)
            active &= ~self._rigid
            loop = self._pdas_loop if cont.strategy == "pdas" else self._active_set_loop
            x, lam, h, active, it_s, up_s = loop(rows, g, active, lam, x)
            iters += it_s
            updates += up_s
            fresh_cand = self._new_contacts(rows, x, x_ref, pz_ref)
            if fresh_cand is None:
                break
            if rnd == cont.detect_rounds:
                raise SolverError(f"contact detection did not settle: {len(fresh_cand[0]) + len(fresh_cand[3])} new "
                                  f"overlapping pairs after {rnd} re-detection rounds (load step too large?)")
            order = np.argsort(rows.keys)
            prev = (rows.keys, active, rows.keys[order], lam[order])
            cand = tuple(np.concatenate([c, f]) for c, f in zip(cand, fresh_cand))
        return self._result(rows, x, lam, h, active, stats0, iters, updates, rnd)

    def _rigid_rows(self, rows, g):
        """Rows on held DOFs only (e.g. a supported node on a fixed plate) cannot move: never
        active; their gap must already be open (else SolverError)."""
        rigid = (abs(rows.C) @ (~self.mask).astype(float)) == 0.0
        if rigid.any():
            hr = g + rows.C @ np.where(self.mask, self.up, 0.0)
            bad = rigid & (hr < -self.dtol)
            if bad.any():
                q = int(np.flatnonzero(bad)[np.argmin(hr[bad])])
                raise SolverError(f"{self._name(rows, q)} overlaps by {-hr[q]:.3e} mm between held DOFs "
                                  "(supports or prescribed plate motion force the penetration)")
        return rigid

    def _start_set(self, rows, prev, warm_keys, warm_forces):
        """Starting active set and multipliers: closed gaps (and the warm contacts) in the first
        round, the previous round's set plus the new candidates after a re-detection."""
        if prev is not None:
            prev_keys, prev_active, keys_sorted, lam_sorted = prev
            old = np.isin(rows.keys, prev_keys[prev_active])
            return old | ~np.isin(rows.keys, prev_keys), _by_key(keys_sorted, lam_sorted, rows.keys)
        if self.contact.strategy == "removal":
            active = np.ones(rows.M, dtype=bool)
        else:
            active = rows.g <= self.gtol
            if warm_keys is not None:
                active |= np.isin(rows.keys, warm_keys)
            try:
                self._check_held(rows, active)
            except SolverError:
                active = np.ones(rows.M, dtype=bool)
        lam = np.zeros(rows.M)
        if warm_keys is not None and warm_forces is not None:
            wk = np.asarray(warm_keys)
            order = np.argsort(wk)
            lam = _by_key(wk[order], np.asarray(warm_forces, dtype=float)[order], rows.keys)
        return active, lam

    def _new_contacts(self, rows, x, x_ref, pz_ref):
        """Candidates (ea, eb, image, plate node, plate) that overlap at the deformed state x but no
        candidate row covers; None when there are none."""
        frame, n, N = self.frame, self.n, self.N
        u = x.reshape(N, 6)
        x_new = frame.nodes + u[:n, :3]
        pz_new = self.plate_z0 + u[n:, 2]
        na, nb, nimg, npn, npi = self._candidates(x_new, pz_new, 0.0)
        if len(na):
            sub = build_rows(frame, x_new, na, nb, nimg, npn[:0], npi[:0], self.plates, pz_new, self.node_r)
            keep = sub.g + self._offset(sub.keys) < -self.dtol
            if keep.any() and rows.n_yarn:
                # drop pairs that duplicate an existing candidate's contact points (shared nodes)
                # (at the linearisation point, where the rows are built)
                ref = build_rows(frame, x_ref, na, nb, nimg, npn[:0], npi[:0], self.plates, pz_ref, self.node_r)
                have = point_keys(frame, rows.ea, rows.eb, rows.image, rows.s, rows.t)
                mine = point_keys(frame, na, nb, nimg, ref.s, ref.t)
                _, inv = np.unique(np.vstack([have, mine]), axis=0, return_inverse=True)
                inv = inv.ravel()
                keep &= ~np.isin(inv[len(have):], inv[:len(have)])
            na, nb, nimg = na[keep], nb[keep], nimg[keep]
        if len(npn):
            gp = np.array([self.plates[p].normal for p in npi]) * (x_new[npn, 2] - pz_new[npi]) - self.node_r[npn]
            keep = gp < -self.dtol
            npn, npi = npn[keep], npi[keep]
        new_keys = np.concatenate([pair_keys(na, nb, nimg, frame.n_elements), plate_keys(npn, npi, n)])
        fresh = ~np.isin(new_keys, rows.keys)
        if not fresh.any():
            return None
        fy, fp = fresh[:len(na)], fresh[len(na):]
        return na[fy], nb[fy], nimg[fy], npn[fp], npi[fp]

    def _result(self, rows, x, lam, h, active, stats0, iters, updates, rnd) -> StaticResult:
        frame, n, N = self.frame, self.n, self.N
        u = x.reshape(N, 6)
        ufr = np.ascontiguousarray(u[:n])
        forces, energy = element_state(frame, ufr, prestrain=self.prestrain)
        c = rows.n_yarn
        pen = np.maximum(-h, 0.0)
        contacts = ContactSet(
            pairs=np.column_stack([rows.ea, rows.eb]), image=rows.image, s=rows.s, t=rows.t,
            normal=rows.normal, gap=rows.g[:c], gap_final=h[:c], force=lam[:c],
            active=active[:c], plate_node=rows.pnode, plate=rows.pidx,
            plate_gap=rows.g[c:], plate_gap_final=h[c:], plate_force=lam[c:], plate_active=active[c:],
            plates=list(self.plates), tangential_force=np.zeros((c, 3)))
        fc = rows.C.T @ lam
        Kx = self.K_ext @ x
        reactions = np.where(self.mask, Kx - self.f - fc, 0.0)[:6 * n].reshape(n, 6)
        check_finite(u=ufr, forces=forces, energy=energy, reactions=reactions, contact_forces=lam)
        st = {k2: self.stats[k2] - stats0[k2] for k2 in self.stats if k2 != "forward_error"}
        st["forward_error"] = self.stats["forward_error"]
        extra = {
            "contact_iterations": iters, "multiplier_updates": updates, "detection_rounds": rnd,
            "plate_displacement": u[n:, 2].copy(), "plate_force": contacts.plate_forces(),
            "contact_energy": float(0.5 * np.dot(lam, pen)), "max_penetration": float(pen.max(initial=0.0)),
            "penalty": self.k, "linear": st, "plate_u": u[n:].copy(), "u_ext": u,
            "active_keys": rows.keys[active], "active_forces": lam[active], "initial_overlaps": self.initial_overlaps,
            "initial_overlap_max": self.initial_overlap_max, "contact_force": fc,
        }
        return StaticResult(frame=frame, u=ufr, report=self._last_rep, forces=forces,
                            energy=dict(zip(ENERGY_KEYS, energy.T.copy())), reactions=reactions,
                            contacts=contacts, extra=extra)


def _by_key(sorted_keys, values, keys):
    """(len(keys),) values[i] where sorted_keys[i] == key, 0 where the key is absent."""
    out = np.zeros(len(keys))
    if len(sorted_keys) and len(keys):
        pos = np.minimum(np.searchsorted(sorted_keys, keys), len(sorted_keys) - 1)
        hit = sorted_keys[pos] == keys
        out[hit] = values[pos[hit]]
    return out


def _new_stats():
    return {"setups": 0, "reused_setups": 0, "setup_seconds": 0.0, "solve_seconds": 0.0, "penalty_increases": 0,
            "linear_solves": 0, "cg_iterations": 0, "forward_error": 0.0, "single_flips": 0,
            "held_unions": 0}


def solve_contact(frame: Frame, fixed=None, loads=None, *, contact: Contact, solver: str | None = None,
                  tol: float | None = None, maxiter: int | None = None, plates=(), assembler=None,
                  u_ref=None, **options) -> StaticResult:
    """``solve_static`` with contact.

    Parameters
    ----------
    plates : list of :class:`~homtex.Plate` (rigid planes), optional.
    u_ref : (n + len(plates), 6) linearisation point (default: the undeformed frame).

    Returns a StaticResult with ``.contacts`` (:class:`ContactSet`) and ``extra`` statistics.
    """
    if options:
        raise InputError(f"unknown solve_static options {sorted(options)} (contact accepts 'plates', 'u_ref')")
    cs = ContactSolver(frame, fixed, loads, contact, plates=plates, solver=solver, tol=tol, maxiter=maxiter,
                       assembler=assembler)
    return cs.solve(u_ref=u_ref)
