"""The linear systems of a contact solve: factorisations, AMG hierarchies reused across
contact iterations, refinement and the conditioning checks."""

from __future__ import annotations

import time

import numpy as np

from ..errors import SolverError
from ..linalg.solvers import LinearSolver

__all__ = ["LinearSystems"]


class LinearSystems:
    """Linear-solver management of :class:`~homtex.contact.solver.ContactSolver` (a mixin)."""

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
                lin = LinearSolver(A, method=self.solver, B=self.B, tol=self.tol, maxiter=self.maxiter,
                                   node_graph=self._element_graph() if self.solver == "amg" else None)
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

    @staticmethod
    def _refine_iterative(lin, A, b, x, passes: int = 2):
        """Iterative refinement of an AMG-CG answer: x += A^-1 (b - A x), each correction solved to
        the solver's relative tolerance (the preconditioner is reused). A CG answer meets its
        tolerance relative to ||b||, and the error it leaves in the contact gaps grows with the
        penalty's conditioning (cond ~ k / beam stiffness); without refinement the augmented
        Lagrangian missed a 1e-10 mm gap tolerance by 4x on the spacer cell (4.3e-10 mm). Each
        correction is solved to a relative 1e-4 (its own residual; solving it to the full tolerance
        took 500-700 CG iterations per pass on a 1.5e4-DOF crossing-beam grid), so each pass
        multiplies the residual by about 1e-4."""
        nb = float(np.linalg.norm(b))
        tol = lin.tol
        lin.tol = max(tol, 1e-4)        # a correction needs a few digits, not the full tolerance
        try:
            for _ in range(passes):
                r = b - A @ x
                if float(np.linalg.norm(r)) <= 1e-15 * nb:
                    break
                try:
                    dx, _ = lin.solve(r)
                except SolverError:
                    break
                x = x + dx
        finally:
            lin.tol = tol
        return x

    def _element_graph(self):
        """(N, N) node graph of the beam elements (plates: isolated nodes), or None with option
        ``contact_aggregation="strength"``: AMG aggregates along yarns only, so contacts (penalty
        springs between yarns) never sit inside an aggregate and every yarn keeps its rigid-body
        modes on the coarse grid."""
        from ..config import option

        if option("contact_aggregation") != "elements":
            return None
        g = getattr(self, "_egraph", None)
        if g is None:
            import scipy.sparse as sp

            el = self.frame.elements
            N = self.N
            r = np.concatenate([el[:, 0], el[:, 1], np.arange(N)])
            c = np.concatenate([el[:, 1], el[:, 0], np.arange(N)])
            g = sp.csr_matrix((np.ones(r.size), (r, c)), shape=(N, N))
            self._egraph = g
        return g

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
        if self.solver == "amg":
            x = self._refine_iterative(lin, A, b, x)
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
