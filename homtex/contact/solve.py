"""Contact solve: enforcement (penalty / augmented Lagrangian) and active-set strategies.

For a linear frame (stiffness K, loads f) and candidate constraints g + C u >= 0 (see
:mod:`homtex.contact.constraints`) the solution minimises 1/2 u K u - f u subject to the
constraints: a convex quadratic programme with a unique answer when K is positive definite
on the admissible motions. Two ways to find its active set:

``"removal"`` (the paper's algorithm, Appendix of Orlik et al.): every candidate starts
    active (as an equality: open gaps are pulled shut), then the most attracting
    ``removal_fraction`` (25 %) of the attracting contacts are removed per iteration until
    none attracts. Contacts are never re-added: if a removed one ends up penetrating, the
    solve fails with that diagnosis (too large a fraction).
``"pdas"`` primal-dual active set (semi-smooth Newton) on the augmented penalty function
    1/2 u K u - f u + sum 1/(2k) max(0, lam - k (g + C u))^2: per iteration the active set is
    {lam - k (g + C u) > 0} (attracting contacts leave, penetrating ones join); every system is
    K + k C_A^T C_A (SPD, never an inconsistent set of equalities); a repeated active set is
    cycling and fails. "augmented" then updates lam <- max(0, lam - k h) until the gaps close
    to ``gap_tol`` (the penalty grows x10 while the updates contract slowly); "penalty" keeps
    lam = 0 (force = k x overlap, overlap checked against ``max_penetration``).

The removal strategy solves each active set as equalities:

``"penalty"`` (K + k C_A^T C_A) u = f - k C_A^T g_A, force lambda = -k (g + C u) (the paper's
    1/gamma = k); the overlap lambda / k remains and must stay below ``max_penetration``.
``"augmented"`` the same operator with Uzawa updates lambda <- lambda - k (g + C u) until the
    gaps close to ``gap_tol``. Contradicting equalities (all candidates closed at the start)
    let their multipliers diverge with opposite signs; the attracting ones are then removed.

With ``solver="amg"`` the AMG hierarchy is reused as the preconditioner of later contact
iterations while the operator changes little (pdas: at most ``reuse_tol`` of the active rows
changed and the same penalty); it is rebuilt when CG needs more than twice the iterations of a
fresh hierarchy. studies/contact_strategies.py measures what this saves.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..errors import InputError, SolverError
from ..fem.assembly import Assembler
from ..model.frame import Frame
from ..linalg.solvers import LinearSolver, constrain, rigid_body_modes
from ..model.scene import check_held, parse_fixed, parse_loads
from .broad import BroadPhase, exclusion_lists
from .constraints import (ContactSet, Plate, build_rows, dedupe_pairs, node_contact_radius, pair_keys,
                          plate_keys, point_keys)

STRATEGIES = ("pdas", "removal")
ENFORCEMENTS = ("augmented", "penalty")


@dataclass
class Contact:
    """Contact options (frictionless, normal contact between yarns and with rigid plates).

    Parameters
    ----------
    strategy : "pdas" (primal-dual active set) or "removal" (the paper's algorithm).
    enforcement : "augmented" (exact gaps, Uzawa updates) or "penalty".
    penalty : contact stiffness k = 1/gamma, N/mm. Default: the mean translational diagonal
        of the frame stiffness (about EA/L of an element).
    removal_fraction : share of the attracting contacts removed per iteration ("removal"), (0, 1].
    margin : search distance added to r_a + r_b, mm (default: the largest contact radius).
    exclude_hops : same-yarn elements this many elements apart or closer are never in
        contact (default: enough to cover the contact diameter, at least 2).
    gap_tol : gap accuracy of "augmented", relative to the mean contact radius.
    max_penetration : largest accepted overlap of "penalty", relative to the smallest contact radius.
    detect_tol : after a solve, pairs not yet candidates that overlap by more than
        detect_tol x smallest contact radius are added and the step re-solved (up to detect_rounds).
    max_iter : active-set iterations; max_updates : multiplier updates per active set.
    reuse_amg : reuse the AMG hierarchy across contact iterations ...
    reuse_tol : ... when at most this share of the active rows changed since it was built (pdas).
    penalty_growth_max : "augmented" multiplies the penalty by 10 (up to this factor) while the
        Uzawa updates contract slowly (nearly dependent contacts).
    initial_overlap : "touch" (default): yarn pairs that overlap in the undeformed frame (a geometry
        artefact) count as touching: their gap is offset to zero, they may separate but not
        overlap further; "resolve": they are pushed apart in the first solve.
    friction : Coulomb coefficient; only 0 (frictionless) is implemented.
    max_forward_error : with the direct solver, each solve is refined once; a relative
        correction above this (an ill-conditioned system, e.g. a penalty far above the beam
        stiffness) raises SolverError instead of returning an inaccurate state.
    """

    strategy: str = "pdas"
    enforcement: str = "augmented"
    penalty: float | None = None
    removal_fraction: float = 0.25
    margin: float | None = None
    exclude_hops: int | None = None
    gap_tol: float = 1e-9
    max_penetration: float = 0.05
    max_iter: int = 200
    max_updates: int = 100
    reuse_amg: bool = True
    reuse_tol: float = 0.05
    detect_rounds: int = 5
    detect_tol: float = 1e-3
    friction: float = 0.0
    penalty_growth_max: float = 1e4
    initial_overlap: str = "touch"
    max_forward_error: float = 1e-6

    def __post_init__(self):
        if self.strategy not in STRATEGIES:
            raise InputError(f"Contact option 'strategy' must be one of {STRATEGIES}, got {self.strategy!r}")
        if self.enforcement not in ENFORCEMENTS:
            raise InputError(f"Contact option 'enforcement' must be one of {ENFORCEMENTS}, "
                             f"got {self.enforcement!r}")
        if self.penalty is not None and not (np.isfinite(self.penalty) and self.penalty > 0):
            raise InputError(f"Contact option 'penalty' must be a positive stiffness (N/mm), got {self.penalty!r}")
        if not (0.0 < self.removal_fraction <= 1.0):
            raise InputError(f"Contact option 'removal_fraction' must lie in (0, 1], got {self.removal_fraction!r}")
        if self.margin is not None and not (np.isfinite(self.margin) and self.margin >= 0):
            raise InputError(f"Contact option 'margin' must be >= 0 (mm), got {self.margin!r}")
        if self.exclude_hops is not None and (int(self.exclude_hops) != self.exclude_hops or self.exclude_hops < 1):
            raise InputError(f"Contact option 'exclude_hops' must be an integer >= 1, got {self.exclude_hops!r}")
        for name in ("gap_tol", "max_penetration", "detect_tol"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise InputError(f"Contact option '{name}' must be positive, got {v!r}")
        for name in ("max_iter", "max_updates", "detect_rounds"):
            v = getattr(self, name)
            if int(v) != v or v < 1:
                raise InputError(f"Contact option '{name}' must be a positive integer, got {v!r}")
        if self.initial_overlap not in ("touch", "resolve"):
            raise InputError(f"Contact option 'initial_overlap' must be 'touch' or 'resolve', "
                             f"got {self.initial_overlap!r}")
        if self.friction != 0.0:
            raise InputError(f"Contact option 'friction' = {self.friction!r}: Coulomb friction is not yet "
                             "implemented (frictionless contact only, friction=0)")


class ContactSolver:
    """A frame with supports, loads, plates and contact options; solves for the contact state.

    The stiffness is assembled once; :meth:`solve` may be called repeatedly (plate motions
    changed with :meth:`set_plate`, linearisation point ``u_ref`` moved), as ``compress`` does.
    Plate p is an extra node n + p whose only free DOF (force control) is uz.
    """

    def __init__(self, frame: Frame, fixed=None, loads=None, contact: Contact | None = None, *,
                 plates=(), solver: str = "amg", tol: float = 1e-10, maxiter: int | None = None,
                 assembler: Assembler | None = None):
        if not isinstance(frame, Frame):
            raise InputError(f"frame must be a homtex.Frame, got {type(frame).__name__}")
        if contact is None:
            contact = Contact()
        if not isinstance(contact, Contact):
            raise InputError(f"contact must be a homtex.Contact, got {type(contact).__name__}")
        plates = list(plates or [])
        for i, p in enumerate(plates):
            if not isinstance(p, Plate):
                raise InputError(f"plates[{i}] must be a homtex.contact.Plate, got {type(p).__name__}")
        if solver not in ("amg", "direct", "cg"):
            raise InputError(f"solver must be one of ('amg', 'direct', 'cg'), got {solver!r}")
        self.frame, self.contact, self.plates = frame, contact, plates
        self.solver, self.tol, self.maxiter = solver, float(tol), maxiter
        n = frame.n_nodes
        P = len(plates)
        self.n, self.P, self.N = n, P, n + P
        mask, up = parse_fixed(fixed, n)
        self.frame_mask = mask
        self.mask = np.concatenate([mask, np.ones(6 * P, dtype=bool)])
        self.up = np.concatenate([up, np.zeros(6 * P)])
        self.f_loads = parse_loads(loads, n)
        self.f = np.concatenate([self.f_loads + _prestrain_load(frame), np.zeros(6 * P)])
        asm = assembler or Assembler(frame)
        self.assembler = asm
        self.set_stiffness(asm.stiffness())
        K = self.K
        d = K.diagonal().reshape(n, 6)[:, :3]
        self.k_scale = float(d.mean())
        self.k = float(contact.penalty) if contact.penalty is not None else self.k_scale
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
        self.node_r = node_contact_radius(frame)
        self.plate_z0 = np.array([float(p.z) for p in plates])
        for i, p in enumerate(plates):
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
        # initial overlaps (gap offsets by pair key)
        self.offset_keys = np.zeros(0, dtype=np.int64)
        self.offset_vals = np.zeros(0)
        if contact.initial_overlap == "touch":
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

    def set_stiffness(self, K):
        """Replace the frame's stiffness (e.g. the co-rotational tangent; same DOFs). The contact
        penalty keeps its scale from the first stiffness; a reused AMG hierarchy is dropped."""
        K = K.tocsr()
        self.K = K
        self.K_ext = sp.block_diag([K, sp.csr_matrix((6 * self.P, 6 * self.P))], format="csr") if self.P else K.copy()
        self._ml = None

    def _offset(self, keys):
        """(len(keys),) gap offset of each candidate (initial overlap treated as touching), mm."""
        return _by_key(self.offset_keys, self.offset_vals, keys)

    # ------------------------------------------------------------------
    def set_plate(self, p: int, *, displacement=None, force=None):
        """Displacement control (mm along z) or force control (N pressing the plate on the yarns)."""
        pl = self.plates[p]
        i = 6 * (self.n + p) + 2
        if force is not None:
            pl.force, pl.displacement = float(force), None
            self.mask[i] = False
            self.up[i] = 0.0
            self.f[i] = pl.normal * float(force)
        else:
            pl.force, pl.displacement = None, float(displacement or 0.0)
            self.mask[i] = True
            self.up[i] = pl.displacement
            self.f[i] = 0.0

    # ------------------------------------------------------------------
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

    def _linear(self, A, signature=None):
        """A LinearSolver for A; with AMG the previous hierarchy is reused when ``signature``
        (active-row keys and penalty) differs from the one it was built for by at most
        ``reuse_tol`` x active rows (the operator changed by a few rank-one terms)."""
        st = self.stats
        t0 = time.perf_counter()
        close = True
        if signature is not None and self._ml is not None:
            keys, k = signature
            old_keys, old_k = self._ml_sig if self._ml_sig is not None else (None, None)
            if old_keys is None or old_k != k:
                close = False
            else:
                changed = len(np.setxor1d(keys, old_keys, assume_unique=True))
                close = changed <= self.contact.reuse_tol * max(len(keys), 1)
        if self.solver == "amg" and self.contact.reuse_amg and self._ml is not None and close:
            lin = LinearSolver(A, method="amg", tol=self.tol, maxiter=self.maxiter, hierarchy=self._ml)
            st["reused_setups"] += 1
        else:
            try:
                lin = LinearSolver(A, method=self.solver, B=self.B, tol=self.tol, maxiter=self.maxiter)
            except RuntimeError as err:     # SuperLU: "Factor is exactly singular"
                raise SolverError(
                    f"{self.solver} factorisation failed ({err}): the contact operator is singular - a rigid "
                    "motion that neither supports nor active contacts hold (e.g. a yarn's spin about its "
                    "own axis, free node rotations of a periodic cell, in-plane sliding on frictionless "
                    "plates); add supports ('fixed') for it") from err
            st["setups"] += 1
            if self.solver == "amg":
                self._ml = lin.ml
                self._ml_sig = signature
                self._base_iters = None
        st["setup_seconds"] += time.perf_counter() - t0
        return lin

    def _lin_solve(self, lin, A, b, x0):
        st = self.stats
        t0 = time.perf_counter()
        try:
            x, rep = lin.solve(b, x0=x0)
        except SolverError as err:
            if self.solver == "direct":
                raise SolverError(
                    f"the contact system is too ill-conditioned for an accurate solve ({err}); the "
                    f"penalty {self.k:.3g} N/mm is too large for these yarns - lower Contact(penalty=...) "
                    f"or use enforcement='augmented'", history=err.history, report=err.report) from err
            if not lin.reused:
                raise
            # a stale hierarchy: rebuild once and retry
            self._ml = None
            lin = self._linear(A)
            x, rep = lin.solve(b, x0=x0)
        if self.solver == "direct":
            # one step of iterative refinement: the size of the correction estimates the forward
            # error, which a large penalty inflates (cond ~ penalty / beam stiffness) while the
            # backward error (the residual) stays at round-off
            x, fwd = lin.refine(b, x)
            st["forward_error"] = max(st.get("forward_error", 0.0), fwd)
            if fwd > self.contact.max_forward_error:
                raise SolverError(
                    f"the contact system is too ill-conditioned for an accurate solve: iterative "
                    f"refinement changes the solution by {fwd:.1e} (relative, limit "
                    f"{self.contact.max_forward_error:g}); the penalty {self.k:.3g} N/mm is too large "
                    f"for these yarns - lower Contact(penalty=...) or use enforcement='augmented'")
        st["solve_seconds"] += time.perf_counter() - t0
        st["linear_solves"] += 1
        st["cg_iterations"] += rep.iterations
        if self.solver == "amg":
            if not rep.reused_setup and self._base_iters is None:
                self._base_iters = max(rep.iterations, 1)
            elif rep.reused_setup and self._base_iters and rep.iterations > 2 * self._base_iters + 10:
                self._ml = None  # too far from the operator it was built for: rebuild next time
        return x, rep, lin

    def _check_held(self, rows, active):
        el = self.frame.elements
        c = rows.n_yarn
        ay = np.flatnonzero(active[:c])
        ap = np.flatnonzero(active[c:])
        mask = self.frame_mask.copy()
        mask[6 * rows.pnode[ap] + 2] = True
        edges = np.column_stack([el[rows.ea[ay], 0], el[rows.eb[ay], 0]])
        check_held(self.frame, mask, edges, rows.image[ay])
        for p, pl in enumerate(self.plates):
            if pl.force_controlled and not np.any(rows.pidx[ap] == p):
                raise SolverError(f"plate {p} ({pl.name or 'force-controlled'}, z = {pl.z}) is held by nothing: "
                                  "no active contact with the yarns (force control needs the plate to touch)")

    # ------------------------------------------------------------------
    def _equality(self, rows, g, active, lam, x0):
        """Solve with the active rows as equalities; returns x (6N,), lam (M,), h (M,), updates."""
        cont = self.contact
        k = self.k
        ia = np.flatnonzero(active)
        Ca = rows.C[ia]
        CtC = (Ca.T @ Ca).tocsr()

        def operator(k):
            Op = (self.K_ext + k * CtC).tocsr()
            if self.P:
                # plate DOFs held fixed need a stored diagonal for the Dirichlet rows
                d = np.zeros(6 * self.N)
                d[6 * self.n:] = np.where(self.mask[6 * self.n:], self.k_scale, 0.0)
                Op = (Op + sp.diags(d)).tocsr()
            A = constrain(sp.bsr_matrix(Op, blocksize=(6, 6)), self.mask)
            return A, A.diagonal(), self.f - Op @ self.up

        A, diag, base = operator(k)
        lin = self._linear(A)
        ga = g[ia]
        la = lam[ia].copy()
        x = x0
        pen_hist = []
        k_max = self.k * cont.penalty_growth_max
        for it in range(1, cont.max_updates + 1):
            # penalty: lambda = -k (g + C u) only; augmented: Uzawa on top of the current multipliers
            b = base - k * (Ca.T @ ga) if cont.enforcement == "penalty" else base + Ca.T @ (la - k * ga)
            b[self.mask] = diag[self.mask] * self.up[self.mask]
            x, rep, lin = self._lin_solve(lin, A, b, x)
            x[self.mask] = self.up[self.mask]
            h = ga + Ca @ x
            if cont.enforcement == "penalty":
                la = -k * h
                break
            la = la - k * h
            err = float(np.abs(h).max()) if h.size else 0.0
            pen_hist.append(err)
            if err <= self.gtol:
                break
            if len(pen_hist) >= 3 and err > 0.3 * pen_hist[-2] and k * 10.0 <= k_max:
                # slow Uzawa contraction (nearly dependent contacts): stiffer augmentation, new operator
                k *= 10.0
                self._ml = None
                A, diag, base = operator(k)
                lin = self._linear(A)
                self.stats["penalty_increases"] += 1
                pen_hist = []
                continue
            stalled = len(pen_hist) > 8 and err > 0.999 * pen_hist[-9]
            if cont.strategy == "removal" and (stalled or it == cont.max_updates or len(pen_hist) >= 20) \
                    and (la < 0).any():
                # contradicting equalities (removal starts with every candidate closed): their
                # multipliers diverge with opposite signs; the attracting ones are removed next
                break
            if it == cont.max_updates or stalled:
                q = ia[int(np.argmax(np.abs(h)))]
                raise SolverError(
                    f"augmented Lagrangian: gaps did not close after {it} multiplier updates "
                    f"(largest |gap| {err:.3e} mm at {self._name(rows, q)}, tolerance {self.gtol:.1e} mm); "
                    f"the contact is held rigidly (both sides supported?) or the penalty {k:.3g} N/mm is far "
                    f"too small", report=rep)
        lam = np.zeros(rows.M)
        lam[ia] = la
        return x, lam, g + rows.C @ x, it, rep

    def _name(self, rows, q):
        c = rows.n_yarn
        if q < c:
            a, b = int(rows.ea[q]), int(rows.eb[q])
            y = self.frame.yarn
            img = f", image {rows.image[q].tolist()}" if rows.image.shape[1] else ""
            return f"yarn-yarn contact elements {a} (yarn {y[a]}) / {b} (yarn {y[b]}{img})"
        q -= c
        return f"yarn-plate contact node {int(rows.pnode[q])} / plate {int(rows.pidx[q])}"

    # ------------------------------------------------------------------
    def solve(self, u_ref=None, warm_keys=None, warm_forces=None):
        """Contact equilibrium linearised about ``u_ref`` (N, 6) (default 0).

        ``warm_keys`` (contact keys active before) start the active set; ``warm_forces`` (same
        length) also start their multipliers (N): Newton steps near convergence move contacts by
        round-off, and a cold multiplier would then let a loaded contact open.

        Returns a :class:`~homtex.static.StaticResult` with ``.contacts`` and ``extra``
        (iterations, linear solves, timings, plate forces and displacements, contact energy).
        """
        from ..analysis.static import ENERGY_KEYS, StaticResult, element_state

        cont = self.contact
        frame = self.frame
        n, N = self.n, self.N
        u_ref = np.zeros((N, 6)) if u_ref is None else np.asarray(u_ref, dtype=float).reshape(N, 6)
        x_ref = frame.nodes + u_ref[:n, :3]
        pz_ref = self.plate_z0 + u_ref[n:, 2]
        target = np.array([self.plate_z0[p] + (pl.displacement if pl.displacement is not None else u_ref[n + p, 2])
                           for p, pl in enumerate(self.plates)])
        ea, eb, img, pn, pi = self._candidates(x_ref, pz_ref, self.margin, target)
        stats0 = dict(self.stats)
        iters = 0
        updates = 0
        x = u_ref.ravel().copy()
        x[self.mask] = self.up[self.mask]
        for rnd in range(cont.detect_rounds + 1):
            rows = build_rows(frame, x_ref, ea, eb, img, pn, pi, self.plates, pz_ref, self.node_r)
            rows.g = rows.g + self._offset(rows.keys)
            g = rows.g - rows.C @ u_ref.ravel()         # constraint g + C u >= 0 in total u
            # rows on held DOFs only (e.g. a supported node on a fixed plate) cannot move: never
            # active; their gap must already be open
            rigid = (abs(rows.C) @ (~self.mask).astype(float)) == 0.0
            if rigid.any():
                hr = g + rows.C @ np.where(self.mask, self.up, 0.0)
                bad = rigid & (hr < -self.dtol)
                if bad.any():
                    q = int(np.flatnonzero(bad)[np.argmin(hr[bad])])
                    raise SolverError(f"{self._name(rows, q)} overlaps by {-hr[q]:.3e} mm between held DOFs "
                                      "(supports or prescribed plate motion force the penetration)")
            self._rigid = rigid
            if rnd == 0:
                if cont.strategy == "removal":
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
            else:
                old = np.isin(rows.keys, prev_keys[prev_active])
                lam = _by_key(prev_keys_sorted, prev_lam_sorted, rows.keys)
                active = old | ~np.isin(rows.keys, prev_keys)
            active &= ~rigid
            if cont.strategy == "pdas":
                x, lam, h, active, it_s, up_s = self._pdas_loop(rows, g, active, lam, x)
            else:
                x, lam, h, active, it_s, up_s = self._active_set_loop(rows, g, active, lam, x)
            iters += it_s
            updates += up_s
            # new contacts at the deformed configuration that no candidate covers
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
                    allk = np.vstack([have, mine])
                    _, inv = np.unique(allk, axis=0, return_inverse=True)
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
                break
            if rnd == cont.detect_rounds:
                raise SolverError(f"contact detection did not settle: {int(fresh.sum())} new overlapping pairs "
                                  f"after {rnd} re-detection rounds (load step too large?)")
            ny = len(na)
            fy, fp = fresh[:ny], fresh[ny:]
            prev_keys, prev_active = rows.keys, active
            order = np.argsort(rows.keys)
            prev_keys_sorted, prev_lam_sorted = rows.keys[order], lam[order]
            ea = np.concatenate([ea, na[fy]])
            eb = np.concatenate([eb, nb[fy]])
            img = np.concatenate([img, nimg[fy]])
            pn = np.concatenate([pn, npn[fp]])
            pi = np.concatenate([pi, npi[fp]])
        # ---- result
        u = x.reshape(N, 6)
        ufr = np.ascontiguousarray(u[:n])
        forces, energy = element_state(frame, ufr)
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
        res = StaticResult(frame=frame, u=ufr, report=self._last_rep, forces=forces,
                           energy=dict(zip(ENERGY_KEYS, energy.T.copy())), reactions=reactions,
                           contacts=contacts, extra=extra)
        return res

    # ------------------------------------------------------------------
    def _penalised(self, rows, g, active, lam, x0, k):
        """Solve (K + k C_A^T C_A) u = f + C_A^T (lam_A - k g_A) (Dirichlet rows kept); returns x, h."""
        ia = np.flatnonzero(active)
        Ca = rows.C[ia]
        Op = (self.K_ext + k * (Ca.T @ Ca)).tocsr()
        if self.P:
            d = np.zeros(6 * self.N)
            d[6 * self.n:] = np.where(self.mask[6 * self.n:], self.k_scale, 0.0)
            Op = (Op + sp.diags(d)).tocsr()
        A = constrain(sp.bsr_matrix(Op, blocksize=(6, 6)), self.mask)
        diag = A.diagonal()
        b = self.f - Op @ self.up + Ca.T @ (lam[ia] - k * g[ia])
        b[self.mask] = diag[self.mask] * self.up[self.mask]
        lin = self._linear(A, (np.sort(rows.keys[ia]), k))
        x, rep, lin = self._lin_solve(lin, A, b, x0)
        x[self.mask] = self.up[self.mask]
        self._last_rep = rep
        return x, g + rows.C @ x

    def _pdas_loop(self, rows, g, active, lam, x):
        """Primal-dual active set on the (augmented) penalty function.

        Inner loop: semi-smooth Newton for min 1/2 u K u - f u + sum 1/(2k) max(0, lam - k (g + C u))^2,
        active set A = {lam - k h > 0}: newly penetrating pairs join, released ones leave. Every
        linear system is SPD (K + k C_A^T C_A), so an inconsistent set of equalities cannot occur.
        Outer loop ("augmented"): lam <- max(0, lam - k h) until gaps close to gap_tol; "penalty"
        stops after one outer pass with lam = 0 (force k x overlap).
        """
        cont = self.contact
        k = self.k
        k_max = self.k * cont.penalty_growth_max
        lam = np.maximum(lam, 0.0) if cont.enforcement == "augmented" else np.zeros(rows.M)
        free = ~self._rigid
        active = active & free
        iters = 0
        hist = []
        for outer in range(1, cont.max_updates + 1):
            seen = {active.tobytes()}
            single = set()          # sets visited after a cycle, changing one contact at a time
            prev = None
            for inner in range(1, cont.max_iter + 1):
                try:
                    self._check_held(rows, active)
                except SolverError:
                    # the update opened every contact that held a part (e.g. the first small plate
                    # step on a structure held only by contacts): keep the previous set's contacts;
                    # a start set that holds nothing (the contacts carried into a re-detection round
                    # are those with force > 0, and a holding contact can end at zero force) starts
                    # from all candidates instead, as the first round does
                    active = active | (free if prev is None else prev)
                    self._check_held(rows, active)
                    self.stats["held_unions"] += 1
                prev = active
                iters += 1
                try:
                    x, h = self._penalised(rows, g, active, lam, x, k)
                except SolverError as err:
                    raise SolverError(f"pdas iteration {iters} ({int(active.sum())} active contacts): {err}",
                                      history=err.history, report=err.report) from err
                # hysteresis of +-eps k on degenerate contacts (zero gap, zero force) against flip-flopping
                eps = 1e-3 * self.gtol
                trial = lam - k * h
                new = np.where(active, trial > -k * eps, trial > k * eps) & free
                if np.array_equal(new, active):
                    break
                key = new.tobytes()
                if key in seen or single:
                    # a cycle of the full Newton update (it happens when several contacts interact
                    # near zero force): change only the most violated contact from here on
                    diff = np.flatnonzero(new != active)
                    q = diff[np.argmax(np.abs(trial[diff]))]
                    flip = active.copy()
                    flip[q] = ~flip[q]
                    if flip.tobytes() in single or flip.tobytes() in seen and single:
                        raise SolverError(f"pdas: the active set cycles (iteration {iters} returns to an earlier set "
                                          f"of {int(new.sum())} contacts, also when changing one contact at a time)")
                    single.add(flip.tobytes())
                    self.stats["single_flips"] += 1
                    new = flip
                else:
                    seen.add(key)
                active = new
            else:
                raise SolverError(f"pdas: the active set did not settle in {cont.max_iter} iterations")
            lam_new = np.where(active, lam - k * h, 0.0)
            if cont.enforcement == "penalty":
                lam = lam_new
                break
            lam = lam_new
            viol = float(max(np.abs(h[active]).max(initial=0.0), (-h[~active & free]).max(initial=0.0)))
            hist.append(viol)
            if viol <= self.gtol:
                break
            if len(hist) >= 3 and viol > 0.3 * hist[-2] and k * 10.0 <= k_max:
                k *= 10.0                      # slow contraction: stiffer augmentation
                self._ml = None
                self.stats["penalty_increases"] += 1
                hist = []
                continue
            if outer == cont.max_updates or (len(hist) > 8 and viol > 0.999 * hist[-9]):
                bad = np.where(active, np.abs(h), np.maximum(-h, 0.0))
                q = int(np.argmax(bad))
                raise SolverError(
                    f"augmented Lagrangian: gaps did not close after {outer} multiplier updates (largest gap "
                    f"error {viol:.3e} mm at {self._name(rows, q)}, tolerance {self.gtol:.1e} mm; penalty "
                    f"{k:.3g} N/mm); the contact is held rigidly or the constraints contradict each other")
        if cont.enforcement == "penalty":
            self._check_penetration(rows, h, active)
        active = lam > 0.0
        return x, lam, h, active, iters, outer

    def _check_penetration(self, rows, h, active):
        """Penalty enforcement: raise when an active contact overlaps by more than
        max_penetration x the smallest contact radius."""
        cont = self.contact
        pen = float(np.maximum(-h[active], 0.0).max(initial=0.0))
        if pen > cont.max_penetration * self.r_min:
            q = int(np.flatnonzero(active)[np.argmin(h[active])])
            raise SolverError(f"penalty too soft: penetration {pen:.3e} mm at {self._name(rows, q)} exceeds "
                              f"max_penetration = {cont.max_penetration} x contact radius {self.r_min:.3g} mm "
                              f"(penalty {self.k:.3g} N/mm); raise 'penalty' or use enforcement='augmented'")

    def _active_set_loop(self, rows, g, active, lam, x):
        cont = self.contact
        seen = {active.tobytes()}
        updates = 0
        for it in range(1, cont.max_iter + 1):
            self._check_held(rows, active)
            try:
                x, lam, h, nup, rep = self._equality(rows, g, active, lam, x)
            except SolverError as err:
                raise SolverError(f"contact iteration {it} ({int(active.sum())} active contacts): {err}",
                                  history=err.history, report=err.report) from err
            self._last_rep = rep
            updates += nup
            ftol = 1e-9 * (float(np.abs(lam).max()) if lam.size else 0.0) + 1e-300
            attracting = active & (lam < -ftol)
            ptol = max(self.gtol, 1e-12 * self.r_mean)
            penetrating = ~active & (h < -ptol) & ~self._rigid
            if cont.strategy == "removal":
                if attracting.any():
                    idx = np.flatnonzero(attracting)
                    nrem = max(1, int(math.ceil(cont.removal_fraction * len(idx))))
                    drop = idx[np.argsort(lam[idx], kind="stable")[:nrem]]
                    active = active.copy()
                    active[drop] = False
                    lam = lam.copy()
                    lam[drop] = 0.0
                    continue
                if penetrating.any():
                    q = int(np.flatnonzero(penetrating)[np.argmin(h[penetrating])])
                    raise SolverError(
                        f"removal strategy: after {it} iterations a removed contact penetrates by "
                        f"{-h[q]:.3e} mm ({self._name(rows, q)}; {int(penetrating.sum())} such); removal_fraction "
                        f"{cont.removal_fraction} removed contacts that are needed - lower it or use strategy='pdas'")
                break
            new = (active & ~attracting) | penetrating
            if np.array_equal(new, active):
                break
            key = new.tobytes()
            if key in seen:
                raise SolverError(f"pdas: the active set cycles (iteration {it} returns to an earlier set of "
                                  f"{int(new.sum())} contacts; {int(attracting.sum())} attracting, "
                                  f"{int(penetrating.sum())} penetrating)")
            seen.add(key)
            lam = np.where(new, lam, 0.0)
            active = new
        else:
            raise SolverError(f"{cont.strategy}: the active set did not settle in {cont.max_iter} iterations")
        if cont.enforcement == "penalty":
            self._check_penetration(rows, h, active)
        return x, lam, h, active, it, updates


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


def _prestrain_load(frame):
    from ..analysis.static import prestrain_load

    return prestrain_load(frame)


def solve_contact(frame: Frame, fixed=None, loads=None, *, contact: Contact, solver: str = "amg",
                  tol: float = 1e-10, maxiter: int | None = None, plates=(), assembler=None,
                  u_ref=None, **options):
    """``solve_static`` with contact (see :mod:`homtex.contact.solve`).

    Parameters
    ----------
    plates : list of :class:`~homtex.contact.Plate` (rigid planes), optional.
    u_ref : (n + len(plates), 6) linearisation point (default: the undeformed frame).

    Returns a StaticResult with ``.contacts`` (:class:`ContactSet`) and ``extra`` statistics.
    """
    if options:
        raise InputError(f"unknown solve_static options {sorted(options)} (contact accepts 'plates', 'u_ref')")
    cs = ContactSolver(frame, fixed, loads, contact, plates=plates, solver=solver, tol=tol, maxiter=maxiter,
                       assembler=assembler)
    return cs.solve(u_ref=u_ref)
