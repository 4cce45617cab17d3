"""The discrete equilibrium problem of a co-rotational frame and its Newton corrector.

R(u, lambda) = lambda f - f_int(u) on the free DOFs; the prescribed DOFs sit at lambda u_bar:
translations add, prescribed rotations are spins about fixed axes (a prescribed rotation vector
ramps its angle about its own axis; components of a node that are not prescribed stay free).
:class:`Equilibrium` keeps the state (translations, rotation matrices, lambda), the element
tangents and the factor of the free-DOF tangent at that state, and :meth:`Equilibrium.correct`
runs Newton's method at a fixed load factor from it (the first iteration is the tangent predictor).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse.linalg as spla

from ..errors import SolverError
from ..fem.corotational_system import apply_increment, element_matvec, element_matvec_serial, spin_between
from .corotational import PARALLEL_ELEMENTS, Corotational
from .tangent import FreeSystem, one_blas_thread, real_negative_eigenvalues

#: largest deformational rotation (rad) an iterate may reach: beyond it the element's local
#: rotation vector nears pi (log map singular) and the co-rotational small-strain element is void
MAX_DEFORMATIONAL_ROTATION = 2.0

#: eigenvalues of the diagonally scaled tangent within +-NEUTRAL of zero are neutral (round-off of a
#: zero-energy mode such as a round rod's bending plane turning about its load: 1e-15 to 1e-13), not
#: unstable; below it, 1e-2 of the structure's softest mode at the start (a rod of L/r = 1e4 reads
#: 3e-11), down to 1e-15
NEUTRAL = 1e-12


class StepFailed(Exception):
    """A corrector that did not reach equilibrium (the step is cut, not reported)."""

    def __init__(self, reason: str, residual: float = np.nan):
        super().__init__(reason)
        self.reason = reason
        self.residual = residual


@dataclass
class Settings:
    """Solver settings shared by every control (see :func:`homtex.solve_nonlinear`)."""

    tol: float = 1e-9
    atol: float | None = None
    max_iter: int = 15
    max_cuts: int = 10
    solver: str = "ldl"
    stability: bool = True
    perturbation: float = 1e-2
    max_correction: float = 1.0
    max_growth: float = 5.0
    desired_iterations: int = 5


class Equilibrium:
    """State, residual and tangent of a frame under loads ``f`` and prescribed motions ``ubar``.

    Parameters
    ----------
    frame : Frame. mask : (6n,) bool constrained DOFs. f : (6n,) reference loads (N, N mm) at
    lambda = 1. ubar : (6n,) prescribed translations (mm) and rotations (rad) at lambda = 1.
    """

    def __init__(self, frame, mask, f, ubar, settings: Settings):
        self.frame = frame
        self.s = settings
        n = frame.n_nodes
        self.n = n
        self.mask = mask
        self.cor = Corotational(frame, geometric="consistent")
        self.sys = FreeSystem(frame, mask, "lu" if settings.solver == "lu" else "ldl")
        self.free = self.sys.free
        self.f = np.asarray(f, dtype=float)
        self.f_free = self.f[self.free]
        self.ubar = np.where(mask, ubar, 0.0).reshape(n, 6)
        self.has_ubar = bool(np.any(self.ubar != 0.0))
        # moments about fixed axes on free DOFs are not conservative in 3D: no energy Hessian; the
        # stability of a state is then the static (divergence) test on the full tangent
        rot = np.zeros((n, 6), dtype=bool)
        rot[:, 3:] = True
        self.nonconservative = bool(np.any(self.f[rot.ravel() & ~mask] != 0.0))
        x = frame.nodes
        span = float(np.linalg.norm(x.max(axis=0) - x.min(axis=0))) if n > 1 else 0.0
        self.length = span if span > 0 else float(frame.length.max())
        # weights of the increment norm: translations (mm) and rotations x the structure size
        w = np.ones((n, 6))
        w[:, 3:] = self.length
        self.w = w.ravel()
        self.floor = 1e-13 * float(np.max(self.cor.arrays[0])) * np.sqrt(n)
        self.lam = 0.0
        self.fint = None            # (6n,) internal forces at the current state
        self.fresh = False          # Ke, fint and the factor belong to the current state
        self.negative = None
        self.evaluations = 0
        self.factorisations = 0
        self.neutral = NEUTRAL

    # -- state
    def snapshot(self):
        return self.cor.ut.copy(), self.cor.Q.copy(), self.lam

    def restore(self, snap, refresh: bool = True):
        self.cor.ut[...] = snap[0]
        self.cor.Q[...] = snap[1]
        self.lam = snap[2]
        self.fresh = False
        if refresh:
            self.refresh()

    def set_neutral(self) -> None:
        """Neutral tolerance from the softest mode of the current (initial, factored) state."""
        try:
            mu = float(self.lowest_modes(1)[0][0])
        except Exception:       # noqa: BLE001 - an eigensolver failure leaves the default
            return
        if mu > 0:
            self.neutral = float(np.clip(1e-2 * mu, 1e-15, NEUTRAL))

    def refresh(self):
        """Forces, element tangents and the factor (with inertia) at the current state."""
        self.evaluate()
        self.factor(inertia=self.s.stability)
        self.fresh = True

    def increment_since(self, snap) -> np.ndarray:
        """(6n,) translations and spins (log Q Q0^T) from ``snap`` to the current state."""
        d = np.empty((self.n, 6))
        d[:, :3] = self.cor.ut - snap[0]
        spin_between(self.cor.Q, snap[1], d[:, 3:])
        return d.ravel()

    def norm(self, v: np.ndarray) -> float:
        """Weighted norm of a (6n,) increment: mm, rotations times the structure size."""
        return float(np.linalg.norm(self.w * v))

    # -- residual and tangent
    def evaluate(self) -> np.ndarray:
        self.fint = self.cor.evaluate_tangent().ravel()
        self.evaluations += 1
        return self.fint

    def residual(self, lam: float) -> np.ndarray:
        return lam * self.f_free - self.fint[self.free]

    def converged(self, rnorm: float, lam: float) -> bool:
        if self.s.atol is not None:
            return rnorm <= self.s.atol
        ref = max(float(np.linalg.norm(lam * self.f)), float(np.linalg.norm(self.fint)))
        return rnorm <= self.s.tol * ref + self.floor

    def factor(self, inertia: bool = False):
        """Assemble and factor the free tangent; ``inertia``: also count its negative eigenvalues
        (LDL^T pivots of the symmetric part; real negative eigenvalues of the full tangent under
        non-conservative moments)."""
        self.sys.assemble(self.cor.Ke)
        self.sys.factor(inertia=inertia and not self.nonconservative)
        self.factorisations += 1
        self.negative = None
        if inertia:
            if self.nonconservative:
                self.negative = real_negative_eigenvalues(self.sys.full(self.cor.Ke))
            else:
                self.negative = self.sys.negative
                if self.negative:
                    self.negative = self._without_neutral(self.negative)

    def _without_neutral(self, raw: int) -> int:
        """Negative pivots of LDL^T that are truly negative eigenvalues: the lowest eigenvalues of the
        scaled tangent below -NEUTRAL (a neutral mode, e.g. the bending plane of a round rod turning
        about its load, reads +-1e-15 and its pivot's sign is round-off)."""
        mu, _ = self.lowest_modes(min(raw + 2, max(self.sys.nf - 1, 1)))
        return int(np.count_nonzero(mu < -self.neutral))

    def k_times(self, v6: np.ndarray) -> np.ndarray:
        """(6n,) K v with the element tangents at the last evaluation (full, nonsymmetric)."""
        p = self.cor.asm.pattern
        out = np.empty((self.n, 6))
        kern = element_matvec if self.frame.n_elements >= PARALLEL_ELEMENTS else element_matvec_serial
        kern(p.node_ptr, p.inc_elem, p.inc_end, self.frame.elements, self.cor.Ke,
                       np.ascontiguousarray(v6.reshape(self.n, 6)), out)
        return out.ravel()

    def tangent_vector(self) -> np.ndarray:
        """(6n,) du / dlambda at the current (fresh: factored) state: the tangent solve on the free
        DOFs, u_bar on the prescribed ones."""
        t = self.ubar.ravel().copy()
        t[self.free] = self.sys.solve(self.load_direction())
        return t

    def lowest_modes(self, k: int = 1):
        """The k eigenvalues of the diagonally scaled free tangent D^-1/2 K D^-1/2 nearest to zero
        (ascending; the scaling keeps the inertia and makes translations and rotations commensurate:
        a neutral mode reads about 1e-15, a bending mode of a very slender rod 1e-11) and their modes
        as (6n, k) increments (free DOFs; unit largest weighted entry), at the last assembly."""
        S = self.sys.symmetric()
        nf = S.shape[0]
        d = np.abs(S.diagonal())
        d = np.where(d > 0, d, max(float(d.max(initial=1.0)), 1.0))
        sc = 1.0 / np.sqrt(d)
        Ss = (S.multiply(sc[:, None]).multiply(sc[None, :])).tocsc()
        k = max(1, min(k, nf - 1))
        if nf <= 400:
            with one_blas_thread():
                mu, V = np.linalg.eigh(Ss.toarray())
            order = np.argsort(np.abs(mu))[:k]
            mu, V = mu[order], V[:, order]
        else:
            try:
                mu, V = spla.eigsh(Ss, k=k, sigma=0.0, which="LM", tol=1e-10)
            except RuntimeError:            # exactly singular: shift a little
                mu, V = spla.eigsh(Ss, k=k, sigma=-1e-8, which="LM", tol=1e-10)
        order = np.argsort(mu)
        mu, V = mu[order], V[:, order] * sc[:, None]
        modes = np.zeros((6 * self.n, len(mu)))
        modes[self.free] = V
        for c in range(modes.shape[1]):
            modes[:, c] /= max(float(np.abs(self.w * modes[:, c]).max()), 1e-300)
        return mu, modes

    def load_direction(self) -> np.ndarray:
        """dR/dlambda on the free DOFs: f - K u_bar (the prescribed motions push the free DOFs)."""
        if not self.has_ubar:
            return self.f_free
        return self.f_free - self.k_times(self.ubar.ravel())[self.free]

    def apply(self, du_free: np.ndarray, dlam_presc: float = 0.0) -> np.ndarray:
        """Add du on the free DOFs and dlam u_bar on the prescribed ones; returns the (6n,) step."""
        du = np.zeros(6 * self.n)
        du[self.free] = du_free
        if dlam_presc != 0.0 and self.has_ubar:
            du += dlam_presc * self.ubar.ravel()
        apply_increment(self.cor.ut, self.cor.Q, du.reshape(self.n, 6))
        self.fresh = False
        return du

    def check_iterate(self, rnorm: float, it: int):
        if not np.isfinite(rnorm):
            raise StepFailed(f"non-finite out-of-balance force at iteration {it}")
        rot = self.cor.max_deformational_rotation()
        if rot > MAX_DEFORMATIONAL_ROTATION:
            raise StepFailed(f"an element turned by {rot:.2f} rad against its chord at iteration {it} "
                             "(step too large for the co-rotational element)", rnorm)

    # -- Newton at a fixed load factor
    def correct(self, lam_new: float, max_step: float | None = None) -> tuple[int, float, np.ndarray]:
        """Newton's method at load factor ``lam_new`` from the current (converged, fresh) state.

        The first iteration is the tangent predictor (with the prescribed increment); returns
        (iterations = linear solves, final residual norm, the predicted (6n,) increment). On
        success the state is converged and fresh (tangent factored, with inertia). ``max_step``:
        largest weighted size of the predictor (StepFailed beyond it: a nearly singular tangent,
        i.e. a limit or turning point ahead).
        """
        if not self.fresh:
            self.refresh()
        dlam = lam_new - self.lam
        rhs = self.residual(lam_new)
        if self.has_ubar and dlam != 0.0:
            rhs = rhs - dlam * self.k_times(self.ubar.ravel())[self.free]
        du = self.sys.solve(rhs)
        if max_step is not None:
            size = float(np.linalg.norm(self.w[self.free] * du))
            if size > max_step:
                raise StepFailed(f"the tangent predictor ({size:.3g}) is larger than {max_step:.3g} (a limit or "
                                 "turning point ahead)")
        pred = self.apply(du, dlam)
        self.lam = lam_new
        it = 1
        first = None
        self.history = []           # out-of-balance force after each linear solve
        self.increments = [float(np.abs(du).max(initial=0.0))]     # largest |du| of each solve
        while True:
            try:
                self.evaluate()
            except SolverError as err:
                raise StepFailed(str(err)) from None
            r = self.residual(lam_new)
            rn = float(np.linalg.norm(r))
            self.history.append(rn)
            self.check_iterate(rn, it)
            if self.converged(rn, lam_new):
                break
            if first is None:
                first = rn
            elif rn > 1e10 * first:
                raise StepFailed(f"Newton iterations diverge (out-of-balance {rn:.3e})", rn)
            if it >= self.s.max_iter:
                raise StepFailed(f"did not converge in {self.s.max_iter} Newton iterations "
                                 f"(out-of-balance force {rn:.3e})", rn)
            self.factor()
            du = self.sys.solve(r)
            self.increments.append(float(np.abs(du).max(initial=0.0)))
            self.apply(du)
            it += 1
        self.factor(inertia=self.s.stability)
        self.fresh = True
        return it, rn, pred

    # -- energies
    def potential_drop(self, lam: float, d_free: np.ndarray, alpha: float, U0: float) -> float:
        """Change of the total potential U - lam f . u along the line alpha d from the state whose
        strain energy is U0 (the external work of dead loads and fixed-axis moments is linear
        along one straight spin/translation step)."""
        return float(self.cor.energy.sum()) - U0 - alpha * lam * float(self.f_free @ d_free)
