"""Optional GPU path of AMG-CG (the ``gpu`` extra: CuPy), written against an array module.

:class:`DeviceAMG` moves a :class:`~homtex.linalg.solvers.ScaledAMG` hierarchy (built on the host,
or reused from earlier solves) to the device as CSR levels with pyamg's Chebyshev coefficients
and a dense inverse of the coarse matrix, and runs the V-cycle and CG there in float64 (level
matrices optionally float32). Every kernel is an ``xp`` call (``xp`` = cupy, or numpy with
scipy.sparse for the tests and for machines without a GPU), so the same code is checked on the
CPU against :class:`~homtex.linalg.parallel_amg.VCycle`.

Selected with ``LinearSolver(..., cycle="gpu")`` or option ``amg_cycle="gpu"``; without CuPy or
a device that raises ImportError naming the extra. :func:`device_solve` reports the phases
(setup, transfer, iterations, per-iteration and solve seconds) of one end-to-end solve.
"""

from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sp

from ..errors import SolverError

__all__ = ["DeviceAMG", "array_module", "device_solve", "gpu_available"]


def gpu_available() -> bool:
    """True when CuPy imports and sees a CUDA device."""
    try:
        import cupy

        return cupy.cuda.runtime.getDeviceCount() > 0
    except Exception:
        return False


def array_module(device: str = "gpu"):
    """(xp, sparse module) for "gpu" (cupy, cupyx.scipy.sparse) or "cpu" (numpy, scipy.sparse)."""
    if device == "cpu":
        return np, sp
    try:
        import cupy
        import cupyx.scipy.sparse as csp
    except ImportError as err:
        raise ImportError("the GPU path needs CuPy: pip install 'homtex[gpu]' (cupy-cuda12x)") from err
    return cupy, csp


class DeviceAMG:
    """A ScaledAMG hierarchy on a device (see the module docstring).

    Parameters
    ----------
    hierarchy : ScaledAMG. A : the (unscaled) operator CG runs on, sparse (n, n).
    device : "gpu" or "cpu". precision : "float64" or "float32" level matrices.

    Attributes: ``transfer_seconds`` (host to device, including the format conversions).
    """

    def __init__(self, hierarchy, A, *, device: str = "gpu", precision: str = "float64"):
        from .parallel_amg import chebyshev_coefficients

        xp, xsp = array_module(device)
        self.xp, self.device = xp, device
        dt = np.float32 if precision == "float32" else np.float64
        t0 = time.perf_counter()

        def put(M, dtype=np.float64):
            C = sp.csr_matrix(M, dtype=dtype)
            C.sort_indices()
            return xsp.csr_matrix(C) if device == "gpu" else C

        ml = hierarchy.ml
        deg = getattr(hierarchy, "degree", 3)
        self.levels = []
        for i, lvl in enumerate(ml.levels[:-1]):
            self.levels.append({"A": put(lvl.A, dt), "P": put(lvl.P, dt), "R": put(lvl.R, dt),
                                "coef": [float(c) for c in chebyshev_coefficients(lvl.A, deg)]})
        Ac = ml.levels[-1].A.toarray()
        self.coarse_inv = xp.asarray(np.linalg.inv(Ac).astype(dt))
        self.scale = xp.asarray(np.asarray(hierarchy.scale, dtype=float))
        self.A = put(A)
        if device == "gpu":
            xp.cuda.Device().synchronize()
        self.transfer_seconds = time.perf_counter() - t0
        self.dtype = dt

    def _mv(self, M, x):
        if M.dtype != x.dtype:
            return (M @ x.astype(M.dtype)).astype(np.float64)
        return M @ x

    def _smooth(self, A, coef, x, b, zero: bool):
        res = b if zero else b - self._mv(A, x)
        h = coef[0] * res
        for c in coef[1:]:
            h = c * res + self._mv(A, h)
        return h if zero else x + h

    def _cycle(self, i, b):
        if i == len(self.levels):
            return self._mv(self.coarse_inv, b)
        L = self.levels[i]
        x = self._smooth(L["A"], L["coef"], None, b, zero=True)
        res = b - self._mv(L["A"], x)
        x = x + self._mv(L["P"], self._cycle(i + 1, self._mv(L["R"], res)))
        return self._smooth(L["A"], L["coef"], x, b, zero=False)

    def precondition(self, r):
        """z = D^-1/2 V(D^-1/2 r) on the device."""
        return self.scale * self._cycle(0, self.scale * r)

    def pcg(self, b, *, x0=None, tol: float = 1e-10, maxiter: int = 1000):
        """CG on the device (the recurrence of homtex.linalg.solvers.pcg); (x, history) with x on
        the device and the history as floats (one device-host sync per iteration)."""
        xp = self.xp
        nb = float(xp.linalg.norm(b))
        x = xp.zeros_like(b) if x0 is None else x0.copy()
        r = b - self.A @ x if x0 is not None else b.copy()
        hist = [float(xp.linalg.norm(r)) / nb]
        if hist[0] <= tol:
            return x, hist
        z = self.precondition(r)
        p = z.copy()
        rz = float(r @ z)
        for it in range(maxiter):
            ap = self.A @ p
            pap = float(p @ ap)
            if not pap > 0.0:
                raise SolverError(f"non-positive curvature p^T A p = {pap:.3e} at CG iteration {it}", history=hist)
            alpha = rz / pap
            x += alpha * p
            r -= alpha * ap
            hist.append(float(xp.linalg.norm(r)) / nb)
            if hist[-1] <= tol:
                break
            z = self.precondition(r)
            rz_new = float(r @ z)
            p = z + (rz_new / rz) * p
            rz = rz_new
        return x, hist


def device_solve(A, b, B, *, tol: float = 1e-8, device: str = "gpu", precision: str = "float64",
                 hierarchy=None, maxiter: int = 1000) -> tuple[np.ndarray, dict]:
    """Solve A x = b end to end with the hierarchy on the device: (x on the host, timings).

    ``hierarchy``: a ScaledAMG to reuse (a changed matrix: CG runs on the new A), else built on
    the host (fast setup). Timings (s): setup, transfer, solve, per_iteration, total; iterations,
    residual (true, on the host)."""
    from .amg import ScaledAMG

    t_all = time.perf_counter()
    t0 = time.perf_counter()
    h = hierarchy if hierarchy is not None else ScaledAMG(A, B)
    t_setup = time.perf_counter() - t0 if hierarchy is None else 0.0
    dev = DeviceAMG(h, A, device=device, precision=precision)
    xp = dev.xp
    t0 = time.perf_counter()
    bd = xp.asarray(np.asarray(b, dtype=float))
    x, hist = dev.pcg(bd, tol=tol, maxiter=maxiter)
    xh = xp.asnumpy(x) if device == "gpu" else np.asarray(x)
    t_solve = time.perf_counter() - t0
    its = len(hist) - 1
    res = float(np.linalg.norm(b - A @ xh) / np.linalg.norm(b))
    return xh, {"setup": t_setup, "transfer": dev.transfer_seconds, "solve": t_solve,
                "per_iteration": t_solve / max(its, 1), "iterations": its, "residual": res,
                "total": time.perf_counter() - t_all, "hierarchy": h}
