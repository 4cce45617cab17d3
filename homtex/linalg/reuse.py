"""Reusing AMG hierarchies across solves of changed matrices with the same pattern.

Load steps, Newton iterations, homogenisation cases and study points on one cell solve matrices
that share a sparsity pattern and change in value. A hierarchy built for one of them is a valid
SPD preconditioner for the others (CG runs on the new matrix, so the answer is exact to the
tolerance); it only costs iterations. :class:`HierarchyCache` keeps one hierarchy per pattern
and rebuilds it by :class:`~homtex.linalg.tangent_backends.ReuseRule`: when the iterations lost
since the last build, priced at the measured time per iteration, exceed the measured setup time,
when a solve needs more than 3x the iterations of a fresh hierarchy, or when the diagonal moved by
more than 50 % (max norm, relative).

Measured (bench_parallel_amg.py, octet block of 8.7e3 DOF, every element's E scaled by a random
factor in [0.8, 1.2]): the old hierarchy needs 60 iterations where a new one needs 54, and saves
its setup.

Used by ``solve_static`` / ``homogenize`` when option ``amg_reuse`` is True (a cache per process,
:data:`CACHE`; ``CACHE.clear()`` empties it).
"""

from __future__ import annotations

import hashlib
import time

import numpy as np

__all__ = ["CACHE", "HierarchyCache", "pattern_key"]


def pattern_key(A) -> str:
    """A fingerprint of the sparsity pattern (shape, block size, index arrays) of a sparse matrix."""
    h = hashlib.blake2b(digest_size=16)
    h.update(np.asarray(A.shape, dtype=np.int64).tobytes())
    h.update(str(getattr(A, "blocksize", (1, 1))).encode())
    h.update(np.ascontiguousarray(A.indptr).tobytes())
    h.update(np.ascontiguousarray(A.indices).tobytes())
    return h.hexdigest()


class HierarchyCache:
    """One ScaledAMG hierarchy per matrix pattern, rebuilt by a ReuseRule (see the module docstring).

    ``get(A, B)`` returns (hierarchy, reused); ``record(A, iterations, seconds)`` feeds the rule
    after a solve. ``max_entries`` patterns are kept (the oldest dropped first).
    """

    def __init__(self, max_entries: int = 4):
        self.max_entries = max_entries
        self._store: dict = {}
        self.builds = 0
        self.reuses = 0

    def clear(self) -> None:
        self._store.clear()

    def get(self, A, B, **kw):
        from .amg import ScaledAMG
        from .tangent_backends import ReuseRule

        key = pattern_key(A)
        d = np.asarray(A.diagonal(), dtype=float)
        ent = self._store.get(key)
        if ent is not None:
            change = float(np.max(np.abs(d - ent["diag"])) / max(np.max(np.abs(ent["diag"])), 1e-300))
            if not ent["rule"].rebuild(change):
                self.reuses += 1
                return ent["h"], True
        t0 = time.perf_counter()
        h = ScaledAMG(A, B, **kw)
        rule = ReuseRule()
        rule.reset(time.perf_counter() - t0)
        self._store.pop(key, None)
        self._store[key] = {"h": h, "rule": rule, "diag": d}
        while len(self._store) > self.max_entries:
            self._store.pop(next(iter(self._store)))
        self.builds += 1
        return h, False

    def record(self, A, iterations: int, seconds: float) -> None:
        ent = self._store.get(pattern_key(A))
        if ent is not None:
            ent["rule"].record(int(iterations), float(seconds))


#: the process-wide cache of option ``amg_reuse``
CACHE = HierarchyCache()
