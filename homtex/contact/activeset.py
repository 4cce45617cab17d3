"""Active-set strategies of the contact solve, and the enforcement of each active set.

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
fresh hierarchy. studies/verification/contact_strategies.py measures what this saves.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.sparse as sp

from ..errors import SolverError
from ..linalg.solvers import constrain

__all__ = ["ActiveSets"]


class ActiveSets:
    """The active-set loops of :class:`~homtex.contact.solver.ContactSolver` (a mixin: they use the
    solver's operator, loads, supports and statistics)."""

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
            for _ in range(1, cont.max_iter + 1):
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
                    f"{k:.3g} N/mm); the contact is held rigidly or the constraints contradict each other"
                    + self._solver_hint())
        if cont.enforcement == "penalty":
            self._check_penetration(rows, h, active)
        active = lam > 0.0
        return x, lam, h, active, iters, outer

    def _solver_hint(self) -> str:
        """With an iterative linear solver, the gaps can only close as far as its tolerance resolves
        the displacements: say so (the failure is then the solver's accuracy, not the contact)."""
        if self.solver == "direct":
            return ""
        return (f"; or the iterative linear solver ({self.solver!r}, tol {self.tol:g}) cannot resolve gaps of "
                f"{self.gtol:.1e} mm: use solver='direct' (the default for contact), a smaller tol, or a larger "
                "Contact(gap_tol=...)")

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
                    f"too small" + self._solver_hint(), report=rep)
        lam = np.zeros(rows.M)
        lam[ia] = la
        return x, lam, g + rows.C @ x, it, rep
