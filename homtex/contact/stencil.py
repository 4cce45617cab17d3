"""Candidate yarn-yarn pairs as four-node stencils (:class:`PairStencil`), built from the broad
phase's pairs (:func:`pair_stencil`, :func:`frame_stencil`) for the pair potential (:mod:`.potential`)
and the collision check (:mod:`.ccd`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError

__all__ = ["PairStencil", "frame_stencil", "node_degree", "pair_stencil"]


@dataclass
class PairStencil:
    """Candidate yarn-yarn pairs as four-node stencils (a0, a1, b0, b1).

    nodes (c, 4) node indices; shift (c, 4, 3) constant offsets (periodic images, mm): the
    stencil's points are x[nodes] + shift. rsum (c,) r_a + r_b (mm); alpha, beta (c, 4) node
    weights (1/deg, (deg-1)/deg). a, b (c,) element indices, image (c, k) image of b.
    length2 (c,) squared reference length of the pair's longer element (mm^2; None: unknown, the
    blend angles stay :attr:`Enforcement.c_range`).
    """

    nodes: np.ndarray
    shift: np.ndarray
    rsum: np.ndarray
    alpha: np.ndarray
    beta: np.ndarray
    a: np.ndarray
    b: np.ndarray
    image: np.ndarray
    length2: np.ndarray | None = None

    def __len__(self):
        return len(self.nodes)

    def points(self, x):
        """(c, 4, 3) stencil points at node positions x (n, 3)."""
        return np.asarray(x, dtype=float)[self.nodes] + self.shift


def node_degree(elements, n_nodes: int) -> np.ndarray:
    """(n,) number of elements at each node."""
    el = np.asarray(elements, dtype=np.int64)
    return np.bincount(el.ravel(), minlength=n_nodes).astype(np.int64)


def pair_stencil(elements, radius, a, b, image=None, periods=None, images=None, degree=None,
                 length=None) -> PairStencil:
    """Stencils of candidate pairs (a, b, image) as returned by the broad phase.

    Parameters
    ----------
    elements : (m, 2) node indices; radius : (m,) contact radius (mm, > 0).
    a, b : (c,) element indices; image : (c, k) integer image of b relative to a.
    periods : (k, 3) lattice vectors (mm); images : (m, k) element images (element e joins
        node i to node j + images[e] @ periods).
    degree : (n,) elements per node (default: counted from ``elements``).
    length : (m,) reference element lengths (mm), for the per-pair blend angles
        (:meth:`Enforcement.pair_c_range`; default None: the global ones).
    """
    el = np.ascontiguousarray(elements, dtype=np.int64)
    if el.ndim != 2 or el.shape[1] != 2:
        raise InputError(f"elements must have shape (m, 2), got {el.shape}")
    m = len(el)
    r = np.asarray(radius, dtype=float)
    if r.shape != (m,) or not (np.isfinite(r).all() and (r > 0).all()):
        raise InputError(f"radius must have shape ({m},) with positive finite values (mm)")
    a = np.ascontiguousarray(a, dtype=np.int64).ravel()
    b = np.ascontiguousarray(b, dtype=np.int64).ravel()
    c = len(a)
    if b.shape != (c,) or (c and (min(a.min(), b.min()) < 0 or max(a.max(), b.max()) >= m)):
        raise InputError(f"a and b must be equal-length element indices in 0..{m - 1}")
    periods = np.zeros((0, 3)) if periods is None else np.asarray(periods, dtype=float).reshape(-1, 3)
    k = len(periods)
    image = np.zeros((c, k), dtype=np.int64) if image is None else np.asarray(image, dtype=np.int64).reshape(c, k)
    images = np.zeros((m, k), dtype=np.int64) if images is None else np.asarray(images, dtype=np.int64).reshape(m, k)
    n = int(el.max()) + 1
    deg = node_degree(el, n) if degree is None else np.asarray(degree, dtype=np.int64)
    nodes = np.ascontiguousarray(np.column_stack([el[a, 0], el[a, 1], el[b, 0], el[b, 1]]))
    shift = np.zeros((c, 4, 3))
    if k:
        shift[:, 1] = images[a] @ periods
        shift[:, 2] = image @ periods
        shift[:, 3] = (image + images[b]) @ periods
    dg = deg[nodes].astype(float)
    L2 = None
    if length is not None:
        L = np.asarray(length, dtype=float)
        if L.shape != (m,) or not (np.isfinite(L).all() and (L > 0).all()):
            raise InputError(f"length must have shape ({m},) with positive finite values (mm)")
        L2 = np.ascontiguousarray(np.maximum(L[a], L[b]) ** 2)
    return PairStencil(nodes=nodes, shift=shift, rsum=np.ascontiguousarray(r[a] + r[b]),
                       alpha=np.ascontiguousarray(1.0 / dg), beta=np.ascontiguousarray((dg - 1.0) / dg),
                       a=a, b=b, image=image, length2=L2)


def frame_stencil(frame, pairs) -> PairStencil:
    """Stencils of broad-phase ``pairs`` (dict with a, b, image) of a :class:`homtex.Frame`."""
    return pair_stencil(frame.elements, frame.contact_radius, pairs["a"], pairs["b"], pairs.get("image"),
                        frame.periods, frame.images, node_degree(frame.elements, frame.n_nodes), frame.length)
