"""Collision-free step bounds: how far a Newton step may go before a yarn passes another.

For node positions x (n, 3) and a search direction dx (n, 3) every candidate pair moves
linearly, x(alpha) = x + alpha dx. :func:`pair_step_bound` returns the largest step (up to a
tolerance) such that no pair's gap g = distance - (r_a + r_b) falls below ``eta`` times its
starting value along [0, alpha], by the additive CCD of C-IPC (Li et al. 2021) with the radii
as thickness:

    after removing the pair's mean motion, no point of the pair moves faster than
    l_p = max(|dx_a0|, |dx_a1|) + max(|dx_b0|, |dx_b1|) relative to the other segment, so the
    gap cannot drop faster than l_p: from a state with gap g, advancing by (g - eta g0) / l_p
    keeps it >= eta g0. Repeat from the new state until the gap is within ``rtol`` of the
    target or the step reaches 1.

It never misses a crossing (each advance is covered by the Lipschitz bound; nothing is
sampled), needs only segment distances, and handles periodic images (constant shifts) and any
motion, rotation-like included. Its cost grows with the relative motion over the gap (sliding
pairs with small gaps take many small advances), capped by ``max_iter`` (the bound returned is
then smaller but still safe). A pair whose starting gap is <= 0 (only possible with a
penalty) is checked on its centre-line distance instead (thickness 0): its centre lines must
not cross.

Plates are exact (a node's gap to a plane is linear in alpha). :func:`displacement_cap` is
the simple alternative of 4C (no node moves more than the smallest contact radius per step):
cheap, but blind to the gaps, so it neither keeps a barrier's gap positive nor lets a far
pair move freely.
"""

from __future__ import annotations

import logging

import numpy as np
from numba import njit, prange

from ..errors import InputError
from .distance import _ee_d2
from .plates import _plate_args, _plates
from .potential import _chunks, _load_stencil, _parallel, _positions
from .stencil import PairStencil

log = logging.getLogger(__name__)


@njit(cache=True)
def _accd(P, dP, xi, eta, rtol, tmax, max_iter, Q):
    """Additive CCD of one pair: safe step in [0, tmax]; returns (t, iterations)."""
    # remove the mean motion; l_p bounds the rate at which the distance can drop
    for i in range(3):
        m = 0.25 * (dP[0, i] + dP[1, i] + dP[2, i] + dP[3, i])
        for k in range(4):
            dP[k, i] -= m
    na = 0.0
    nb = 0.0
    for k in range(4):
        v = np.sqrt(dP[k, 0] ** 2 + dP[k, 1] ** 2 + dP[k, 2] ** 2)
        if k < 2:
            na = max(na, v)
        else:
            nb = max(nb, v)
    lp = na + nb
    if lp <= 0.0:
        return tmax, 0
    d = np.sqrt(_ee_d2(P))
    if d - xi <= 0.0:
        xi = 0.0                       # penetrating start (penalty): keep the centre lines apart
    gap0 = d - xi
    if gap0 <= 0.0:
        return 0.0, 0
    target = eta * gap0
    t = 0.0
    gap = gap0
    for it in range(max_iter):
        dt = (gap - target) / lp
        if t + dt >= tmax:
            return tmax, it + 1
        t += dt
        for k in range(4):
            for i in range(3):
                Q[k, i] = P[k, i] + t * dP[k, i]
        gap = np.sqrt(_ee_d2(Q)) - xi
        if gap - target <= rtol * (gap0 - target):
            return t, it + 1
    return t, max_iter


@njit(cache=True)
def _pair_bounds_chunk(x, dx, nodes, shift, rsum, eta, rtol, tmax, max_iter, use_radii, lo, hi, toi, iters):
    P = np.empty((4, 3))
    dP = np.empty((4, 3))
    Q = np.empty((4, 3))
    for q in range(lo, hi):
        _load_stencil(x, nodes, shift, q, P)
        for k in range(4):
            for i in range(3):
                dP[k, i] = dx[nodes[q, k], i]
        toi[q], iters[q] = _accd(P, dP, rsum[q] if use_radii else 0.0, eta, rtol, tmax, max_iter, Q)


@njit(cache=True)
def _pair_bounds_ser(x, dx, nodes, shift, rsum, eta, rtol, tmax, max_iter, use_radii, toi, iters):
    _pair_bounds_chunk(x, dx, nodes, shift, rsum, eta, rtol, tmax, max_iter, use_radii, 0, nodes.shape[0],
                       toi, iters)


@njit(cache=True, parallel=True)
def _pair_bounds_par(x, dx, nodes, shift, rsum, eta, rtol, tmax, max_iter, use_radii, nch, toi, iters):
    c = nodes.shape[0]
    for ch in prange(nch):
        _pair_bounds_chunk(x, dx, nodes, shift, rsum, eta, rtol, tmax, max_iter, use_radii, ch * c // nch,
                           (ch + 1) * c // nch, toi, iters)


def _check_eta(eta):
    if not (0.0 <= eta < 1.0):
        raise InputError(f"eta (fraction of the starting gap to keep) must lie in [0, 1), got {eta!r}")


def pair_step_bound(x, dx, stencil: PairStencil, eta: float = 0.1, rtol: float = 0.05,
                    max_iter: int = 10_000, use_radii: bool = True, return_pairs: bool = False) -> float | tuple:
    """Largest safe step alpha in [0, 1] for the yarn-yarn pairs of ``stencil``.

    Parameters
    ----------
    x, dx : (n, 3) node positions and step direction (mm).
    stencil : candidate pairs; they must include every pair that can come into contact along
        the step (see :func:`step_candidates`).
    eta : keep each gap >= eta x its starting value (0 <= eta < 1).
    rtol : stop refining a pair once its gap is within rtol of the way to the target.
    use_radii : measure gaps from the yarn surfaces (True: a barrier) or the centre lines (False:
        a penalty, which must be free to penetrate but not to pass through).
    return_pairs : also return each pair's bound and its iterations.

    Returns alpha (float), or (alpha, toi (c,), iterations (c,)).
    """
    x = _positions(x, int(stencil.nodes.max()) + 1 if len(stencil) else None)
    dx = _positions(dx)
    if dx.shape != x.shape:
        raise InputError(f"dx must have the shape of x {x.shape}, got {dx.shape}")
    _check_eta(eta)
    c = len(stencil)
    toi = np.ones(c)
    iters = np.zeros(c, dtype=np.int64)
    if c:
        args = (x, dx, stencil.nodes, stencil.shift, stencil.rsum, float(eta), float(rtol), 1.0, int(max_iter),
                bool(use_radii))
        if _parallel(c, "ccd"):
            _pair_bounds_par(*args, _chunks(c), toi, iters)
        else:
            _pair_bounds_ser(*args, toi, iters)
    alpha = float(toi.min()) if c else 1.0
    if c and iters.max() >= max_iter:
        log.debug("pair_step_bound: %d pairs hit max_iter=%d (bound stays safe, may be small)",
                  int((iters >= max_iter).sum()), max_iter)
    return (alpha, toi, iters) if return_pairs else alpha


def plate_step_bound(x, dx, nodes, radius, origin, normal, plate=0, plate_motion=None, eta: float = 0.1,
                     use_radii: bool = True, return_nodes: bool = False) -> float | tuple:
    """Largest step alpha in [0, 1] keeping every node's plate gap >= eta x its starting value.

    ``plate_motion`` (P, 3): the plates' motion along the same step (mm). Gaps are linear in
    alpha, so the bound is exact. A node that starts with a gap <= 0 (or every node, with
    ``use_radii=False``: a penalty, which must be free to penetrate) is held to its centre
    (thickness 0); one whose centre is already beyond the plane does not limit the step.
    """
    x = _positions(x)
    dx = _positions(dx)
    o, nr = _plates(origin, normal)
    nodes, radius, plate = _plate_args(x, nodes, radius, plate, len(o))
    _check_eta(eta)
    dpl = np.zeros((len(o), 3)) if plate_motion is None else np.asarray(plate_motion, dtype=float).reshape(-1, 3)
    n = nr[plate]
    dist = np.einsum("ij,ij->i", x[nodes] - o[plate], n)
    g0 = dist - radius if use_radii else dist
    g0 = np.where(g0 > 0, g0, dist)                  # penetrating start: centre line
    rate = np.einsum("ij,ij->i", dx[nodes] - dpl[plate], n)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where((rate < 0) & (g0 > 0), (1.0 - eta) * g0 / -rate, 1.0)
    t = np.clip(t, 0.0, 1.0)
    alpha = float(t.min()) if len(t) else 1.0
    return (alpha, t) if return_nodes else alpha


def displacement_cap(dx, r_min: float) -> float:
    """Step bound of the simple alternative: no node moves more than ``r_min`` (mm)."""
    dx = _positions(dx)
    if not (np.isfinite(r_min) and r_min > 0):
        raise InputError(f"r_min (smallest contact radius, mm) must be positive, got {r_min!r}")
    m = float(np.sqrt(np.einsum("ij,ij->i", dx, dx)).max()) if len(dx) else 0.0
    return 1.0 if m <= r_min else r_min / m


def step_candidates(broad, x, dx, ghat: float = 0.0) -> dict:
    """Broad-phase pairs that can come within ghat of contact along x + alpha dx, alpha in [0, 1].

    ``broad`` is a :class:`homtex.contact.broad.BroadPhase`: its search margin is widened by
    twice the largest node motion (two segments approach by at most that much).
    """
    dx = _positions(dx)
    m = float(np.sqrt(np.einsum("ij,ij->i", dx, dx)).max()) if len(dx) else 0.0
    return broad.pairs(x, float(ghat) + 2.0 * m)
