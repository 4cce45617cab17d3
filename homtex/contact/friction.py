"""Lagged, smoothed Coulomb friction for yarn-yarn pairs and yarn-plate nodes (IPC style).

At the lag state x_lag (the start of the step, or of a lag iteration) every active contact j (a
yarn-yarn pair or a node on a plate) freezes its normal force lambda_j (N), its closest-point
weights c_j (the barycentric coefficients of its stencil nodes) and a tangent basis T_j (3 x 2,
orthonormal, orthogonal to its normal). Over the step from x_start to x its tangential slip is

    u_j = T_j^T (sum_k c_jk (x_k - x_start_k) - d_j)      (mm, 2-vector)

(d_j: the motion of a rigid plate at the contact over the step; 0 for pairs) and the friction
potential is D = sum_j mu_j lambda_j f0(|u_j|), with IPC's C1 mollifier

    f0(y) = -y^3 / (3 eps^2) + y^2 / eps + eps / 3   (y < eps),   f0(y) = y   (y >= eps).

eps (mm) is the slip at which friction saturates: for |u| >= eps the force on the contact is
mu lambda against the slip (sliding), below it a stiff elastic stick of at most mu lambda.
The force is -grad D; the Hessian of one contact, mu lambda c c^T (x) T M T^T with
M = f1(y)/y I + (f1'(y) y - f1(y))/y^3 u u^T, is positive semi-definite (f0(|u|) is convex
and the slip linear in x). A yarn-yarn pair rubs once: at its segments' closest points, in the
plane normal to the contact (the common perpendicular of the segments' lines, which is the smooth
yarns' normal also where a segment's closest point is clamped to its end; near parallel, where that
is undefined, the segments' own, blended as the potential blends its forms), with its share of its
contact patch's net normal force. The net of a pair is the sum of its contact potential's
inclusion-exclusion terms (:mod:`.potential`); a patch is the pairs that share a node of either
yarn, and its net normal force goes to its pairs in proportion to their positive nets, so every
pair presses (lambda >= 0: friction only dissipates) and the patch presses with what the potential
gives it. (Rubbing each term at its own closest point with its signed weight is exact for a rigid
slide but gives energy back where the slip varies along a contact that spreads over several
elements: -0.87 N mm against 0.005 N mm of work on the acrylic rib, docs/contact.md.) A rigid slide
rubs at mu N, N the patch's normal force, for any number of pairs and any crossing angle.

The energy friction dissipates over a step is its force at the end of the step times the step's
slip, sum_j mu_j lambda_j f1(|u_j|) |u_j| (mu lambda s for a slip s >= eps): the lagged potential
is an implicit-Euler step of a rate-regularised law whose force is that of the end state throughout
the step. (The work of the regularised force along the straight path, mu lambda (s - eps / 3) when
sliding, would miss mu lambda eps / 3 per step and contact, because the potential restarts from
zero slip every step while the contact keeps sliding: 3 % of the work of a thin yarn (r = 0.01 mm)
slid by 15 r in 200 steps.)
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numba import njit, prange
from scipy.sparse.csgraph import connected_components

from ..errors import InputError
from .distance import _d2_at, _ee_classify, _sin2_angle
from .plates import _plate_args, _plates
from .potential import (
    Enforcement,
    _blend,
    _chunks,
    _load_stencil,
    _parallel,
    _phi,
    _positions,
    _scatter,
    _term_params,
    _term_weights,
    pair_gaps,
)
from .stencil import PairStencil

log = logging.getLogger(__name__)

#: sin^2 of the crossing angles between which a pair's friction normal turns from its rubbing
#: points' (near parallel) to the common perpendicular of its segments' lines (crossing)
LINE_NORMAL_SIN2 = (float(np.sin(np.radians(4.0)) ** 2), float(np.sin(np.radians(8.0)) ** 2))


# ----------------------------------------------------------------------------------------
@njit(cache=True, inline="always")
def _mollifier(y, eps):
    """(f0, f1/y, (f1' y - f1)/y^3) of IPC's friction mollifier at y >= 0."""
    if y >= eps:
        return y, 1.0 / y, -1.0 / (y * y * y)
    f0 = -y * y * y / (3.0 * eps * eps) + y * y / eps + eps / 3.0
    f1y = -y / (eps * eps) + 2.0 / eps
    if y > 0.0:
        return f0, f1y, -1.0 / (y * eps * eps)
    return f0, f1y, 0.0


def friction_mollifier(y, eps: float) -> tuple:
    """IPC's mollifier f0 and f1 = f0' at slips y >= 0 (mm); eps > 0 (mm). Returns (f0, f1)."""
    y = np.abs(np.asarray(y, dtype=float))
    f0 = np.where(y < eps, -y ** 3 / (3 * eps ** 2) + y ** 2 / eps + eps / 3, y)
    f1 = np.where(y < eps, -y ** 2 / eps ** 2 + 2 * y / eps, 1.0)
    return f0, f1


@njit(cache=True, inline="always")
def _basis(nx, ny, nz, T, j):
    """Orthonormal tangents of unit normal n into T[j] (3, 2)."""
    ax = abs(nx)
    ay = abs(ny)
    az = abs(nz)
    # cross n with the coordinate axis least aligned with it
    if ax <= ay and ax <= az:
        t1x, t1y, t1z = 0.0, -nz, ny
    elif ay <= az:
        t1x, t1y, t1z = nz, 0.0, -nx
    else:
        t1x, t1y, t1z = -ny, nx, 0.0
    nn = np.sqrt(t1x * t1x + t1y * t1y + t1z * t1z)
    t1x /= nn
    t1y /= nn
    t1z /= nn
    T[j, 0, 0] = t1x
    T[j, 1, 0] = t1y
    T[j, 2, 0] = t1z
    T[j, 0, 1] = ny * t1z - nz * t1y
    T[j, 1, 1] = nz * t1x - nx * t1z
    T[j, 2, 1] = nx * t1y - ny * t1x


@njit(cache=True)
def _pair_lag_chunk(x, nodes, shift, rsum, alpha, beta, idx, kind, kp, ghat, c0, c1, lo, hi, lam, coef, T):
    """Lagged friction of active pairs idx[lo:hi]: net normal force lam (na,) (signed), closest-point
    weights coef (na, 1, 4), tangents T (na, 1, 3, 2) of the contact normal."""
    P = np.empty((4, 3))
    gc = np.empty(12)
    Hc = np.empty((1, 1))
    for r in range(lo, hi):
        q = idx[r]
        _load_stencil(x, nodes, shift, q, P)
        d2e, es, et, ecase = _ee_classify(P)
        s2 = _sin2_angle(P, gc, Hc, 0)
        w, w1, w2 = _blend(s2, c0[q], c1[q])
        net = 0.0
        wsum = 0.0
        cs = 0.0
        ct = 0.0
        for j in range(9):
            W, Wp = _term_weights(j, w, alpha[q], beta[q])
            if W == 0.0:
                continue
            s, t, fs, ft = _term_params(P, j, es, et, ecase)
            d = np.sqrt(_d2_at(P, s, t))
            if d - rsum[q] >= ghat or d <= 0.0:
                continue
            e, e1, e2 = _phi(d - rsum[q], kind, kp, ghat)
            net -= W * e1
            # the rubbing point: the terms' closest points weighted by their force magnitudes, a
            # point on each segment that moves smoothly (the segments' own closest point jumps
            # between their ends as they turn parallel)
            a = abs(W * e1)
            wsum += a
            cs += a * s
            ct += a * t
        lam[r] = net
        if wsum > 0.0:
            es = cs / wsum
            et = ct / wsum
        coef[r, 0, 0] = 1.0 - es
        coef[r, 0, 1] = es
        coef[r, 0, 2] = -(1.0 - et)
        coef[r, 0, 3] = -et
        n = np.zeros(3)
        for k in range(4):
            for i in range(3):
                n[i] += coef[r, 0, k] * P[k, i]
        nn = np.sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2])
        if nn <= 0.0:       # the weighted points met (cores cannot): the segments' closest points
            d2e, es, et, ecase = _ee_classify(P)
            coef[r, 0, 0] = 1.0 - es
            coef[r, 0, 1] = es
            coef[r, 0, 2] = -(1.0 - et)
            coef[r, 0, 3] = -et
            n[:] = 0.0
            for k in range(4):
                for i in range(3):
                    n[i] += coef[r, 0, k] * P[k, i]
            nn = np.sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2])
        n /= nn
        # the contact normal is normal to both yarns. Near parallel: the rubbing points' direction
        # less its part along the yarns' mean tangent (a pair offset along the yarns would lean);
        # crossing: the common perpendicular of the segments' lines, the smooth yarns' normal also
        # for a pair beside the crossing; between them a blend v (the perpendicular turns with any
        # skew as the yarns turn parallel)
        ea = P[1] - P[0]
        eb = P[3] - P[2]
        tb = ea / np.sqrt(ea @ ea)
        tc = eb / np.sqrt(eb @ eb)
        if tb @ tc < 0.0:
            tc = -tc
        tm = tb + tc
        tm /= np.sqrt(tm @ tm)
        npar = n - (n @ tm) * tm
        nn = np.sqrt(npar @ npar)
        if nn > 1e-6:
            n = npar / nn
        v = 1.0 - _blend(s2, LINE_NORMAL_SIN2[0], LINE_NORMAL_SIN2[1])[0]
        m = np.cross(ea, eb)
        mm = np.sqrt(m @ m)
        if v > 0.0 and mm > 0.0:
            m /= mm
            if m @ n < 0.0:
                m = -m
            m = v * m + (1.0 - v) * n
            n = m / np.sqrt(m @ m)
        _basis(n[0], n[1], n[2], T[r], 0)


@njit(cache=True)
def _pair_lag(x, nodes, shift, rsum, alpha, beta, idx, kind, kp, ghat, c0, c1, lam, coef, T):
    _pair_lag_chunk(x, nodes, shift, rsum, alpha, beta, idx, kind, kp, ghat, c0, c1, 0, idx.size, lam, coef, T)


@njit(cache=True)
def _friction_chunk(x, x0, nodes, coef, T, lam, mu, dref, eps, hess, project, lo, hi,
                    e_out, dis_out, slip_out, g_out, H_out):
    """Friction energy, dissipation, slips, gradient (np, 3S) and Hessian (np, 3S, 3S)."""
    S = nodes.shape[1]
    J = lam.shape[1]
    B = 3 * S
    d = np.empty(3)
    Hl = np.empty((B, B))
    for r in range(lo, hi):
        E = 0.0
        dis = 0.0
        for i in range(B):
            g_out[r, i] = 0.0
            if hess:
                for m in range(B):
                    Hl[i, m] = 0.0
        for j in range(J):
            lj = lam[r, j]
            slip_out[r, j] = 0.0
            if lj == 0.0:
                continue
            # a negative normal force (only in a hand-built lag: the lag functions give none) makes a
            # concave term; projecting, its Hessian is left out (each kept one is PSD)
            skip_h = project and lj < 0.0
            for i in range(3):
                d[i] = -dref[r, i]
            for k in range(S):
                ck = coef[r, j, k]
                nd = nodes[r, k]
                for i in range(3):
                    d[i] += ck * (x[nd, i] - x0[nd, i])
            u0 = T[r, j, 0, 0] * d[0] + T[r, j, 1, 0] * d[1] + T[r, j, 2, 0] * d[2]
            u1 = T[r, j, 0, 1] * d[0] + T[r, j, 1, 1] * d[1] + T[r, j, 2, 1] * d[2]
            y = np.sqrt(u0 * u0 + u1 * u1)
            f0, f1y, f2 = _mollifier(y, eps)
            ml = mu[r] * lj
            E += ml * f0
            dis += ml * f1y * y * y
            slip_out[r, j] = y
            # tangential force direction in 3D: T u
            v0 = T[r, j, 0, 0] * u0 + T[r, j, 0, 1] * u1
            v1 = T[r, j, 1, 0] * u0 + T[r, j, 1, 1] * u1
            v2 = T[r, j, 2, 0] * u0 + T[r, j, 2, 1] * u1
            for k in range(S):
                a = ml * f1y * coef[r, j, k]
                g_out[r, 3 * k] += a * v0
                g_out[r, 3 * k + 1] += a * v1
                g_out[r, 3 * k + 2] += a * v2
            if hess and not skip_h:
                # 3 x 3 core: f1/y T T^T + f2 (T u)(T u)^T
                for i in range(3):
                    vi = v0 if i == 0 else (v1 if i == 1 else v2)
                    for m in range(3):
                        vm = v0 if m == 0 else (v1 if m == 1 else v2)
                        core = ml * (f1y * (T[r, j, i, 0] * T[r, j, m, 0] + T[r, j, i, 1] * T[r, j, m, 1])
                                     + f2 * vi * vm)
                        for k in range(S):
                            for l in range(S):
                                Hl[3 * k + i, 3 * l + m] += coef[r, j, k] * coef[r, j, l] * core
        e_out[r] = E
        dis_out[r] = dis
        if hess:
            H_out[r] = Hl


@njit(cache=True)
def _friction_ser(x, x0, nodes, coef, T, lam, mu, dref, eps, hess, project, e_out, dis_out, slip_out, g_out, H_out):
    _friction_chunk(x, x0, nodes, coef, T, lam, mu, dref, eps, hess, project, 0, nodes.shape[0],
                    e_out, dis_out, slip_out, g_out, H_out)


@njit(cache=True, parallel=True)
def _friction_par(x, x0, nodes, coef, T, lam, mu, dref, eps, hess, project, nch,
                  e_out, dis_out, slip_out, g_out, H_out):
    npair = nodes.shape[0]
    for ch in prange(nch):
        _friction_chunk(x, x0, nodes, coef, T, lam, mu, dref, eps, hess, project, ch * npair // nch,
                        (ch + 1) * npair // nch, e_out, dis_out, slip_out, g_out, H_out)


# ----------------------------------------------------------------------------------------
@dataclass
class FrictionLag:
    """Lagged friction contacts (frozen at x_lag).

    nodes (np, S) stencil nodes (S = 4 for pairs, 1 for plates); coef (np, J, S) closest-point
    weights of each term (J = 1: one rubbing point per pair or plate node); basis (np, J, 3, 2)
    tangents; lam (np, J) normal forces (N, >= 0 from the lag functions); mu (np,) friction coefficients;
    index (np,) the candidate each row comes from; plate (np,) plate of each row (-1 for pairs).
    """

    nodes: np.ndarray
    coef: np.ndarray
    basis: np.ndarray
    lam: np.ndarray
    mu: np.ndarray
    index: np.ndarray
    plate: np.ndarray

    def __len__(self):
        return len(self.nodes)

    @property
    def normal_force(self) -> np.ndarray:
        """(np,) net lagged normal force of each row (N)."""
        return self.lam.sum(axis=1)


@dataclass
class FrictionEval:
    """Friction potential over a step.

    energy (N mm, including the constant mu lambda eps/3 per contact); dissipation (N mm: the
    friction forces at x times the slips from x_start); grad (n, 3) (N; force = -grad); hess (np, B, B)
    blocks over hess_nodes (np, S); slip (np, J) tangential slips (mm); plate_force (P, 3) force
    of friction on each plate (N; plate rows only, else zeros).
    """

    energy: float
    dissipation: float
    grad: np.ndarray
    hess: np.ndarray | None
    hess_nodes: np.ndarray
    slip: np.ndarray
    plate_force: np.ndarray


def friction_coefficients(mu, type_a=None, type_b=None, n: int | None = None) -> np.ndarray:
    """Per-contact friction coefficients from a scalar or an (ntypes, ntypes) table.

    ``mu`` scalar: every contact; a symmetric table: mu[type_a, type_b] (yarn types of the two
    elements); an (n,) array: one value per contact. Values must be finite and >= 0.
    """
    m = np.asarray(mu, dtype=float)
    if not (np.isfinite(m).all() and (m >= 0).all()):
        raise InputError(f"mu (friction coefficient) must be finite and >= 0, got {mu!r}")
    if m.ndim == 0:
        if n is None:
            n = 0 if type_a is None else len(type_a)
        return np.full(n, float(m))
    if m.ndim == 2:
        if m.shape[0] != m.shape[1] or not np.allclose(m, m.T):
            raise InputError(f"mu table must be square and symmetric (ntypes, ntypes), got shape {m.shape}")
        if type_a is None or type_b is None:
            raise InputError("a mu table needs type_a and type_b (the yarn types of each contact)")
        ta = np.asarray(type_a, dtype=np.int64)
        tb = np.asarray(type_b, dtype=np.int64)
        if len(ta) and (min(ta.min(), tb.min()) < 0 or max(ta.max(), tb.max()) >= len(m)):
            raise InputError(f"type_a/type_b must index the {len(m)} x {len(m)} mu table")
        return np.ascontiguousarray(m[ta, tb])
    if n is not None and m.shape != (n,):
        raise InputError(f"mu must be a scalar, a table or have shape ({n},), got {m.shape}")
    return np.ascontiguousarray(m.ravel())


def pair_friction_lag(x_lag, stencil: PairStencil, enforcement: Enforcement, mu=0.0) -> FrictionLag:
    """Freeze the yarn-yarn friction contacts at positions x_lag (n, 3).

    ``mu``: scalar or (c,) per candidate (see :func:`friction_coefficients`). Rows: the pairs
    active at x_lag with mu > 0, each rubbing once (module docstring): at its segments' closest
    points, along the contact normal, with its share of its patch's net normal force.
    """
    x = _positions(x_lag, int(stencil.nodes.max()) + 1 if len(stencil) else None)
    mu_c = friction_coefficients(mu, n=len(stencil))
    from_gap = pair_gaps(x, stencil)
    idx = np.flatnonzero((from_gap < enforcement.cutoff) & (mu_c > 0)).astype(np.int64)
    na = len(idx)
    net = np.zeros(na)
    coef = np.zeros((na, 1, 4))
    T = np.zeros((na, 1, 3, 2))
    if na:
        if enforcement.kind in ("barrier", "shell") and from_gap[idx].min() <= 0:
            raise InputError("x_lag: a pair's gap is <= 0, where the barrier is infinite")
        c0, c1 = enforcement.pair_c_range(stencil)
        _pair_lag(x, stencil.nodes, stencil.shift, stencil.rsum, stencil.alpha, stencil.beta, idx,
                  enforcement.code, enforcement.params, enforcement.cutoff, c0, c1, net, coef, T)
    lam = patch_shares(net, stencil.nodes[idx], stencil.shift[idx])[:, None]
    return FrictionLag(nodes=stencil.nodes[idx], coef=coef, basis=T, lam=lam, mu=mu_c[idx], index=idx,
                       plate=np.full(na, -1, dtype=np.int64))


def contact_patches(nodes, shift) -> np.ndarray:
    """(np,) patch label of each pair: pairs that share a node of either yarn (at the same periodic
    offset) touch the same contact patch. nodes (np, 4) stencil nodes (a0, a1, b0, b1); shift
    (np, 4, 3) their periodic offsets (mm, :class:`~.stencil.PairStencil`)."""
    n = len(nodes)
    if not n:
        return np.zeros(0, dtype=np.int64)
    # offsets are sums of lattice vectors: rounding only merges what is equal up to round-off
    rel = np.round(np.asarray(shift, dtype=float) - np.asarray(shift, dtype=float)[:, :1], 6)
    keys = np.vstack([np.c_[nodes[:, i], nodes[:, j], rel[:, j] - rel[:, i]] for i in (0, 1) for j in (2, 3)])
    _, key = np.unique(keys, axis=0, return_inverse=True)
    rows = np.tile(np.arange(n), 4)
    link = sp.csr_matrix((np.ones(4 * n), (rows, key.ravel())), shape=(n, int(key.max()) + 1))
    return connected_components(link @ link.T, directed=False)[1]


def patch_shares(net, nodes, shift) -> np.ndarray:
    """Nonnegative normal forces (np,) N: each patch's net normal force shared among its pairs in
    proportion to their positive nets (a pair whose inclusion-exclusion terms sum below zero corrects
    its neighbours; on its own it would rub against the slip)."""
    net = np.asarray(net, dtype=float)
    if not len(net):
        return net
    lab = contact_patches(nodes, shift)
    pos = np.clip(net, 0.0, None)
    total = np.bincount(lab, weights=net)
    total_pos = np.bincount(lab, weights=pos)
    scale = np.where(total_pos > 0.0, np.clip(total, 0.0, None) / np.where(total_pos > 0.0, total_pos, 1.0), 0.0)
    return pos * scale[lab]


def plate_friction_lag(x_lag, nodes, radius, origin, normal, enforcement: Enforcement, plate=0,
                       mu=0.0) -> FrictionLag:
    """Freeze the node-plate friction contacts at x_lag (arguments as :func:`.plates.plate_potential`)."""
    x = _positions(x_lag)
    o, nr = _plates(origin, normal)
    nodes, radius, plate = _plate_args(x, nodes, radius, plate, len(o))
    mu_c = friction_coefficients(mu, n=len(nodes))
    gap = np.einsum("ij,ij->i", x[nodes] - o[plate], nr[plate]) - radius
    idx = np.flatnonzero((gap < enforcement.cutoff) & (mu_c > 0))
    e, e1, e2 = enforcement.energy(gap[idx])
    if not np.isfinite(e1).all():
        raise InputError("x_lag: a node's plate gap is <= 0, where the barrier is infinite")
    na = len(idx)
    T = np.zeros((na, 1, 3, 2))
    for r in range(na):
        n = nr[plate[idx[r]]]
        _basis(n[0], n[1], n[2], T[r], 0)
    return FrictionLag(nodes=nodes[idx][:, None], coef=np.ones((na, 1, 1)), basis=T, lam=-e1[:, None],
                       mu=mu_c[idx], index=idx, plate=plate[idx])


def friction_potential(lag: FrictionLag, x, x_start, eps_v: float, plate_motion=None, hessian: bool = True,
                       project: bool = True) -> FrictionEval:
    """Lagged friction potential at x (n, 3) for the step from x_start (n, 3).

    eps_v : slip (mm, > 0) at which friction saturates. plate_motion : (P, 3) displacement of
    each plate over the step (mm; plate rows). project : leave terms with a negative normal force
    (a hand-built lag) out of the Hessian.
    """
    x = _positions(x)
    x0 = _positions(x_start)
    if x0.shape != x.shape:
        raise InputError(f"x_start must have the shape of x {x.shape}, got {x0.shape}")
    if not (np.isfinite(eps_v) and eps_v > 0):
        raise InputError(f"eps_v (slip at which friction saturates, mm) must be positive, got {eps_v!r}")
    npair, S = lag.nodes.shape if len(lag) else (0, lag.nodes.shape[1] if lag.nodes.ndim == 2 else 1)
    J = lag.lam.shape[1] if lag.lam.ndim == 2 else 1
    dref = np.zeros((npair, 3))
    nplates = 0
    if (lag.plate >= 0).any():
        if plate_motion is None:
            plate_motion = np.zeros((int(lag.plate.max()) + 1, 3))
        pm = np.asarray(plate_motion, dtype=float).reshape(-1, 3)
        nplates = len(pm)
        sel = lag.plate >= 0
        dref[sel] = pm[lag.plate[sel]]
    e = np.zeros(npair)
    dis = np.zeros(npair)
    slip = np.zeros((npair, J))
    g = np.zeros((npair, 3 * S))
    H = np.zeros((npair, 3 * S, 3 * S)) if hessian else np.zeros((0, 3 * S, 3 * S))
    if npair:
        args = (x, x0, lag.nodes, lag.coef, lag.basis, lag.lam, lag.mu, dref, float(eps_v), hessian, project)
        if _parallel(npair, "friction"):
            _friction_par(*args, _chunks(npair), e, dis, slip, g, H)
        else:
            _friction_ser(*args, e, dis, slip, g, H)
    grad = np.zeros_like(x)
    _scatter(lag.nodes, np.arange(lag.nodes.shape[0]), g, grad)
    pf = np.zeros((nplates, 3))
    if nplates:
        sel = np.flatnonzero(lag.plate >= 0)
        np.add.at(pf, lag.plate[sel], g[sel, :3])
    return FrictionEval(energy=float(e.sum()), dissipation=float(dis.sum()), grad=grad,
                        hess=H if hessian else None, hess_nodes=lag.nodes, slip=slip, plate_force=pf)
