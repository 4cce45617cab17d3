"""Smooth contact potentials for large motion: yarn-yarn pairs (plates: :mod:`.plates`).

Enforcement on the gap g (mm) = centre-line distance - (r_a + r_b) (radii as offsets; for a
plate g = n . (x - p) - r), all zero for g >= ghat and C2 there, kappa in N/mm:

* ``"barrier"`` (IPC, Li et al. 2020): b(g) = -kappa (g - ghat)^2 ln(g / ghat), infinite at
  g = 0, so every state must stay intersection-free (line search capped by :mod:`.ccd`);
* ``"penalty"`` (C2 smoothed quadratic): kappa (ghat - g)^3 / (6 ghat) on [0, ghat) and
  kappa g^2 / 2 - kappa ghat g / 2 + kappa ghat^2 / 6 for g < 0: a linear penalty of stiffness
  kappa whose contact surface sits at g = ghat / 2, rounded C2 over [0, ghat]; it tolerates
  penetration with a constant tangent stiffness kappa;
* ``"cubic"``: kappa (ghat - g)^3 / (3 ghat) for all g < ghat (stiffens without bound);
* ``"shell"`` (a compressible yarn: a soft shell over a hard core; :mod:`.compression`): the
  barrier at the cores' surfaces (g measured from the cores) plus a power law over the shells,
  k / (n + 1) (s - g)^(n + 1) for g < s: the force k delta^n at an indentation delta = s - g of
  the outer surfaces (s: the two shells' thickness), active from g < max(ghat, s).

Pair energy (segments a = (x0, x1), b = (x2, x3); ``c`` = sin^2 of their angle; node weights
alpha_v = 1 / deg(v), beta_v = (deg(v) - 1) / deg(v), deg = number of elements at the node):

    E = (1 - w(c)) X + w(c) P,   w = 1 for c <= c0, 0 for c >= c1, quintic smoothstep between,
    X = b(EE) - sum_v beta_v b(PE(v, other)) + sum_{v in a, u in b} beta_v beta_u b(PP(v, u)),
    P = sum_{v in a} alpha_v [b(PE(v, b)) - sum_{u in b} beta_u b(PP(v, u))] + (a <-> b),

with EE, PE, PP the segment-segment, end-segment and end-end gaps. X (crossing yarns) is an
inclusion-exclusion over the cells of the product of the two chains: summed over all pairs
it counts each contact point once, also while it passes a node (a plain sum over segment
pairs counts a contact at a shared node twice or four times, a ripple that acts like a
spurious friction when yarns slide). P (near-parallel yarns: the line-line formula is singular
and the closest point jumps between the two ends) is a nodal quadrature of the line contact
from both sides, likewise free of double counting: a smooth, well-defined force distribution.
Every term is a C1 function of the positions, so E is C1 everywhere (C2 except where a
closest-point case changes).

Gradients are w.r.t. node positions x (n, 3) = reference + translations; the contact force on
the nodes is -grad. Hessians come per active pair as 12 x 12 blocks over the stencil's four
nodes (optionally projected to positive semi-definite by clamping eigenvalues, :mod:`.psd`),
ready to be scattered onto the translational DOFs 6 node + 0..2 (:func:`assemble_blocks` for
tests and small problems).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numba
import numpy as np
import scipy.sparse as sp
from numba import njit, prange

from ..errors import InputError
from .distance import _d2_at, _ee_classify, _pe_param, _sin2_angle, _stencil_d2
from .psd import _project_psd, _project_single
from .stencil import PairStencil

log = logging.getLogger(__name__)

KINDS = {"barrier": 0, "penalty": 1, "cubic": 2, "shell": 3}


# ----------------------------------------------------------------------------------------
# enforcement functions of the gap
@njit(cache=True, inline="always")
def _phi(g, kind, kp, cutoff):
    """(energy, d/dg, d2/dg2) of the enforcement at gap g; kp = (kappa, ghat, shell, shell
    stiffness, shell exponent) (:attr:`Enforcement.params`), cutoff the activation gap."""
    if g >= cutoff:
        return 0.0, 0.0, 0.0
    if kind == 3:
        e, e1, e2 = 0.0, 0.0, 0.0
        if g < kp[1]:
            if g <= 0.0:
                return np.inf, -np.inf, np.inf
            dg = g - kp[1]
            lg = np.log(g / kp[1])
            e = -kp[0] * dg * dg * lg
            e1 = -kp[0] * (2.0 * dg * lg + dg * dg / g)
            e2 = -kp[0] * (2.0 * lg + 4.0 * dg / g - dg * dg / (g * g))
        if g < kp[2]:
            q = kp[2] - g
            n = kp[4]
            qn = q ** n
            e += kp[3] * q * qn / (n + 1.0)
            e1 -= kp[3] * qn
            e2 += kp[3] * n * q ** (n - 1.0)
        return e, e1, e2
    kappa = kp[0]
    ghat = cutoff
    if kind == 0:
        if g <= 0.0:
            return np.inf, -np.inf, np.inf
        dg = g - ghat
        lg = np.log(g / ghat)
        return (-kappa * dg * dg * lg, -kappa * (2.0 * dg * lg + dg * dg / g),
                -kappa * (2.0 * lg + 4.0 * dg / g - dg * dg / (g * g)))
    if kind == 1:
        if g >= 0.0:
            q = ghat - g
            return kappa * q * q * q / (6.0 * ghat), -kappa * q * q / (2.0 * ghat), kappa * q / ghat
        return (0.5 * kappa * g * g - 0.5 * kappa * ghat * g + kappa * ghat * ghat / 6.0,
                kappa * g - 0.5 * kappa * ghat, kappa)
    q = ghat - g
    return kappa * q * q * q / (3.0 * ghat), -kappa * q * q / ghat, 2.0 * kappa * q / ghat


@njit(cache=True)
def _phi_array(g, kind, kp, cutoff, e, e1, e2):
    for i in range(g.size):
        e[i], e1[i], e2[i] = _phi(g[i], kind, kp, cutoff)


@njit(cache=True, inline="always")
def _blend(c, c0, c1):
    """Weight of the parallel form: 1 for c <= c0, 0 for c >= c1; returns (w, dw/dc, d2w/dc2)."""
    if c <= c0:
        return 1.0, 0.0, 0.0
    if c >= c1:
        return 0.0, 0.0, 0.0
    h = c1 - c0
    u = (c - c0) / h
    S = u * u * u * (10.0 - 15.0 * u + 6.0 * u * u)
    S1 = 30.0 * u * u * (1.0 - u) * (1.0 - u)
    S2 = 60.0 * u * (1.0 - u) * (1.0 - 2.0 * u)
    return 1.0 - S, -S1 / h, -S2 / (h * h)


@dataclass(frozen=True)
class Enforcement:
    """How contact is enforced.

    Parameters
    ----------
    kind : "barrier", "penalty", "cubic" or "shell" (see the module docstring).
    ghat : activation gap, mm (> 0): pairs with gap >= ghat carry no force (``"shell"``: the
        barrier's; the shell acts from gap ``shell``).
    kappa : stiffness, N/mm (> 0).
    shell : ``"shell"``: thickness of the compressible shells over the cores, mm (the two of a
        pair together; > 0). shell_stiffness : k of the force k delta^n, N/mm^n (> 0).
    shell_exponent : n (>= 1).
    parallel_deg : (theta0, theta1) degrees: pairs closer to parallel than theta0 use the
        nodal (line-contact) form, pairs beyond theta1 the crossing form, a C2 blend between.
    project : project each pair's 12 x 12 Hessian block to positive semi-definite.
    parallel_sagitta : the nodal form's worst error at a crossing, as a share of ghat (> 0): two
        segments of length L at an angle theta crossing at their middles are (L sin theta)^2 /
        (8 r_sum) farther apart at their end points than at the crossing, where the nodal form looks;
        a pair whose longer element makes that exceed parallel_sagitta x ghat at theta0 gets both
        angles lowered by the same factor (:meth:`pair_c_range`). Thin filaments on long elements
        otherwise pass through each other unseen by the potential (the collision check stops them
        and Newton stalls).
    """

    kind: str = "barrier"
    ghat: float = 0.01
    kappa: float = 1.0
    parallel_deg: tuple = (1.0, 2.0)
    project: bool = True
    shell: float = 0.0
    shell_stiffness: float = 0.0
    shell_exponent: float = 1.0
    parallel_sagitta: float = 0.3

    def __post_init__(self):
        if self.kind not in KINDS:
            raise InputError(f"Enforcement.kind must be one of {sorted(KINDS)}, got {self.kind!r}")
        if self.kind == "shell":
            for name, lo in (("shell", 0.0), ("shell_stiffness", 0.0)):
                v = getattr(self, name)
                if not (np.isfinite(v) and v > lo):
                    raise InputError(f"Enforcement.{name} must be positive and finite for kind 'shell', got {v!r}")
            if not (np.isfinite(self.shell_exponent) and 1.0 <= self.shell_exponent <= 20.0):
                raise InputError(f"Enforcement.shell_exponent must lie in [1, 20], got {self.shell_exponent!r}")
        for name in ("ghat", "kappa"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise InputError(f"Enforcement.{name} must be positive and finite, got {v!r}")
        if not (np.isfinite(self.parallel_sagitta) and self.parallel_sagitta > 0):
            raise InputError(f"Enforcement.parallel_sagitta must be positive and finite, got {self.parallel_sagitta!r}")
        t0, t1 = (float(v) for v in self.parallel_deg)
        if not (0.0 <= t0 < t1 < 90.0):
            raise InputError(f"Enforcement.parallel_deg must satisfy 0 <= theta0 < theta1 < 90, got "
                             f"{self.parallel_deg!r}")

    @property
    def code(self) -> int:
        return KINDS[self.kind]

    @property
    def cutoff(self) -> float:
        """Activation gap, mm: terms with a larger gap carry no force."""
        return max(self.ghat, self.shell) if self.kind == "shell" else self.ghat

    @property
    def params(self) -> np.ndarray:
        """(5,) (kappa, ghat, shell, shell stiffness, shell exponent), as the kernels take them."""
        return np.array([self.kappa, self.ghat, self.shell, self.shell_stiffness, self.shell_exponent], dtype=float)

    @property
    def c_range(self):
        t0, t1 = np.radians(np.asarray(self.parallel_deg, dtype=float))
        return float(np.sin(t0) ** 2), float(np.sin(t1) ** 2)

    def pair_c_range(self, stencil: PairStencil) -> tuple:
        """((c,), (c,)) sin^2 of the blend angles of every pair of ``stencil``: :attr:`c_range`,
        both lowered by one factor where the nodal form's error at a crossing (the sagitta (L^2 c0) /
        (8 r_sum) of the longer element L) would exceed ``parallel_sagitta`` x ghat."""
        c0, c1 = self.c_range
        n = len(stencil)
        scale = np.ones(n)
        if stencil.length2 is not None and n and c0 > 0:
            with np.errstate(divide="ignore"):
                limit = 8.0 * self.parallel_sagitta * self.ghat * stencil.rsum / stencil.length2
            scale = np.minimum(1.0, limit / c0)
        return np.ascontiguousarray(c0 * scale), np.ascontiguousarray(c1 * scale)

    def energy(self, g):
        """(energy N mm, d/dg N, d2/dg2 N/mm) at gaps g (any shape, mm)."""
        g = np.asarray(g, dtype=float)
        flat = np.ascontiguousarray(g.ravel())
        e, e1, e2 = (np.empty_like(flat) for _ in range(3))
        _phi_array(flat, self.code, self.params, self.cutoff, e, e1, e2)
        return e.reshape(g.shape), e1.reshape(g.shape), e2.reshape(g.shape)


# ----------------------------------------------------------------------------------------
# the terms of one pair: 0 EE, 1-2 PE(a_k, b), 3-4 PE(b_k, a), 5-8 PP(a_i, b_k) (5 + 2 i + k)
@njit(cache=True, inline="always")
def _term_params(P, j, ee_s, ee_t, ee_case):
    """(s, t, free_s, free_t) of term j of stencil P."""
    if j == 0:
        return ee_s, ee_t, (ee_case == 4 or ee_case == 5 or ee_case == 8), (ee_case >= 6)
    if j <= 2:
        s = float(j - 1)
        t = _pe_param(P, True, j - 1)
        return s, t, False, (0.0 < t < 1.0)
    if j <= 4:
        t = float(j - 3)
        s = _pe_param(P, False, j - 3)
        return s, t, (0.0 < s < 1.0), False
    i = (j - 5) // 2
    k = (j - 5) % 2
    return float(i), float(k), False, False


@njit(cache=True, inline="always")
def _term_weights(j, w, al, be):
    """(W, dW/dw) of term j for blend weight w, node weights al, be (4,)."""
    if j == 0:
        return 1.0 - w, -1.0
    if j <= 4:
        v = j - 1                      # stencil slot of the end point: 0, 1 (a), 2, 3 (b)
        return -(1.0 - w) * be[v] + w * al[v], be[v] + al[v]
    i = (j - 5) // 2
    k = 2 + (j - 5) % 2
    x = be[i] * be[k]
    y = al[i] * be[k] + al[k] * be[i]
    return (1.0 - w) * x - w * y, -x - y


@njit(cache=True)
def _load_stencil(x, nodes, shift, q, P):
    for k in range(4):
        nd = nodes[q, k]
        for i in range(3):
            P[k, i] = x[nd, i] + shift[q, k, i]


@njit(cache=True)
def _pair_energy(P, R, al, be, kind, kp, ghat, c0, c1, hess, gout, Hout, tg, tH, gc, Hc, Gp):
    """Energy, gradient (gout) and Hessian (Hout) of one pair.

    Returns (E, lam, gap_ee, nterm, s, t, free_s, free_t): lam the pair's net normal force (N),
    -sum_j W_j phi'(g_j); nterm the number of terms that contributed (-1 inside the parallel
    blend) and the case of the last one (for the reduced PSD projection of a single term).
    """
    d2e, es, et, ecase = _ee_classify(P)
    gap_ee = np.sqrt(d2e) - R
    for i in range(12):
        gout[i] = 0.0
        if hess:
            for j in range(12):
                Hout[i, j] = 0.0
    if gap_ee >= ghat:
        return 0.0, 0.0, gap_ee, 0, 0.0, 0.0, False, False
    if (kind == 0 or kind == 3) and gap_ee <= 0.0:
        return np.inf, np.inf, gap_ee, 0, 0.0, 0.0, False, False
    c = _sin2_angle(P, gc, Hc, 0)
    w, w1, w2 = _blend(c, c0, c1)
    blend = w1 != 0.0 or w2 != 0.0
    if blend:
        c = _sin2_angle(P, gc, Hc, 2 if hess else 1)
        for i in range(12):
            Gp[i] = 0.0
    E = 0.0
    Q = 0.0
    lam = 0.0
    nterm = 0
    s1 = t1 = 0.0
    fs1 = ft1 = False
    for j in range(9):
        W, Wp = _term_weights(j, w, al, be)
        if W == 0.0 and not (blend and Wp != 0.0):
            continue
        s, t, fs, ft = _term_params(P, j, es, et, ecase)
        d2 = _d2_at(P, s, t)
        d = np.sqrt(d2)
        if d - R >= ghat:
            continue
        d2 = _stencil_d2(P, s, t, fs, ft, tg, tH, hess)
        d = max(np.sqrt(d2), 1e-300)
        e, e1, e2 = _phi(d - R, kind, kp, ghat)
        nterm += 1
        s1, t1, fs1, ft1 = s, t, fs, ft
        E += W * e
        lam -= W * e1
        a1 = e1 / (2.0 * d)
        for i in range(12):
            gout[i] += W * a1 * tg[i]
        if hess:
            a2 = (e2 / (4.0 * d2) - e1 / (4.0 * d2 * d))
            for i in range(12):
                for m in range(12):
                    Hout[i, m] += W * (a2 * tg[i] * tg[m] + a1 * tH[i, m])
        if blend:
            Q += Wp * e
            for i in range(12):
                Gp[i] += Wp * a1 * tg[i]
    if blend:
        for i in range(12):
            gout[i] += w1 * Q * gc[i]
        if hess:
            for i in range(12):
                for m in range(12):
                    Hout[i, m] += (w1 * (gc[i] * Gp[m] + Gp[i] * gc[m]) + w2 * Q * gc[i] * gc[m]
                                   + w1 * Q * Hc[i, m])
        nterm = -1
    return E, lam, gap_ee, nterm, s1, t1, fs1, ft1


@njit(cache=True)
def _pair_gaps_chunk(x, nodes, shift, rsum, lo, hi, gap):
    P = np.empty((4, 3))
    for q in range(lo, hi):
        _load_stencil(x, nodes, shift, q, P)
        d2, s, t, case = _ee_classify(P)
        gap[q] = np.sqrt(d2) - rsum[q]


@njit(cache=True)
def _pair_gaps_ser(x, nodes, shift, rsum, gap):
    """Segment-segment gap of every pair (values only)."""
    _pair_gaps_chunk(x, nodes, shift, rsum, 0, nodes.shape[0], gap)


@njit(cache=True, parallel=True)
def _pair_gaps_par(x, nodes, shift, rsum, nch, gap):
    c = nodes.shape[0]
    for ch in prange(nch):
        _pair_gaps_chunk(x, nodes, shift, rsum, ch * c // nch, (ch + 1) * c // nch, gap)


@njit(cache=True)
def _pair_eval_chunk(x, nodes, shift, rsum, alpha, beta, idx, kind, kp, ghat, c0, c1, hess, project,
                     lo, hi, e_out, lam_out, g_out, H_out):
    P = np.empty((4, 3))
    tg = np.empty(12)
    tH = np.empty((12, 12))
    gc = np.empty(12)
    Hc = np.empty((12, 12))
    Gp = np.empty(12)
    Hl = np.empty((12, 12))
    Bm = np.empty((12, 5))
    M = np.empty((5, 5))
    V = np.empty((5, 5))
    for r in range(lo, hi):
        q = idx[r]
        _load_stencil(x, nodes, shift, q, P)
        E, lam, gap, nterm, s, t, fs, ft = _pair_energy(P, rsum[q], alpha[q], beta[q], kind, kp, ghat, c0[q],
                                                        c1[q], hess, g_out[r], Hl, tg, tH, gc, Hc, Gp)
        e_out[r] = E
        lam_out[r] = lam
        if hess:
            if project and nterm == 1:
                _project_single(P, s, t, fs, ft, Hl, Bm, M, V)
            elif project and nterm != 0:
                _project_psd(Hl)
            H_out[r] = Hl


@njit(cache=True)
def _pair_eval_ser(x, nodes, shift, rsum, alpha, beta, idx, kind, kp, ghat, c0, c1, hess, project,
                   e_out, lam_out, g_out, H_out):
    """Energy, net normal force, gradient (na, 12) and Hessian (na, 12, 12) of pairs idx."""
    _pair_eval_chunk(x, nodes, shift, rsum, alpha, beta, idx, kind, kp, ghat, c0, c1, hess, project,
                     0, idx.size, e_out, lam_out, g_out, H_out)


@njit(cache=True, parallel=True)
def _pair_eval_par(x, nodes, shift, rsum, alpha, beta, idx, kind, kp, ghat, c0, c1, hess, project, nch,
                   e_out, lam_out, g_out, H_out):
    na = idx.size
    for ch in prange(nch):
        _pair_eval_chunk(x, nodes, shift, rsum, alpha, beta, idx, kind, kp, ghat, c0, c1, hess, project,
                         ch * na // nch, (ch + 1) * na // nch, e_out, lam_out, g_out, H_out)


@njit(cache=True)
def _scatter(nodes, idx, g, out):
    """out[nodes[idx[r], k]] += g[r, 3k:3k+3] (serial: no races)."""
    for r in range(idx.size):
        q = idx[r]
        for k in range(nodes.shape[1]):
            nd = nodes[q, k]
            for i in range(3):
                out[nd, i] += g[r, 3 * k + i]


# ----------------------------------------------------------------------------------------
@dataclass
class ContactEval:
    """Contact potential at one state.

    energy (N mm); grad (n, 3) dE/dx (N; the contact force on the nodes is -grad);
    gap (c,) segment-segment (or node-plate) gap of every candidate (mm); lam (c,) net normal
    force per candidate (N, > 0 pushes apart; 0 when inactive; a pair's share of the
    inclusion-exclusion, so sums over pairs are the physical forces); active (na,) indices of the
    candidates with gap < ghat; hess (na, B, B) Hessian blocks of the active ones (B = 12 for
    pairs, 3 for plates) over hess_nodes (na, B/3); plate_force (P, 3) force of the yarns on
    each plate (N; plates only).
    """

    energy: float
    grad: np.ndarray
    gap: np.ndarray
    lam: np.ndarray
    active: np.ndarray
    hess: np.ndarray | None
    hess_nodes: np.ndarray
    plate_force: np.ndarray | None = None

    @property
    def n_active(self) -> int:
        return int(len(self.active))

    @property
    def min_gap(self) -> float:
        return float(self.gap.min()) if len(self.gap) else np.inf


# below this many items a kernel runs serially (measured, bench_contact_kernels.py): on an idle
# machine two threads halve the time, but a parallel region waits for every thread, and on a
# shared machine whose other core is busy that costs a scheduler tick (4-8 ms) per call, and
# spinning worker threads slow the serial code around it
PARALLEL_MIN = {"gaps": 200000, "ccd": 20000, "eval": 5000, "friction": 50000}


def _chunks(n):
    """Number of work chunks for n items (a few per thread; one per item when few)."""
    return max(1, min(n, 4 * numba.get_num_threads()))


def _parallel(n, key):
    return numba.get_num_threads() > 1 and n >= PARALLEL_MIN[key]


def _positions(x, n_min=None):
    x = np.ascontiguousarray(x, dtype=float)
    if x.ndim != 2 or x.shape[1] != 3:
        raise InputError(f"x must have shape (n, 3) (node positions, mm), got {x.shape}")
    if not np.isfinite(x).all():
        raise InputError("x (node positions) must be finite")
    if n_min is not None and len(x) < n_min:
        raise InputError(f"x has {len(x)} nodes but the contact set refers to node {n_min - 1}")
    return x


def pair_gaps(x, stencil: PairStencil) -> np.ndarray:
    """(c,) segment-segment gaps (mm) of the stencil's pairs at positions x (n, 3)."""
    x = _positions(x, int(stencil.nodes.max()) + 1 if len(stencil) else None)
    gap = np.empty(len(stencil))
    if len(stencil):
        args = (x, stencil.nodes, stencil.shift, stencil.rsum)
        if _parallel(len(stencil), "gaps"):
            _pair_gaps_par(*args, _chunks(len(stencil)), gap)
        else:
            _pair_gaps_ser(*args, gap)
    return gap


def pair_potential(x, stencil: PairStencil, enforcement: Enforcement, hessian: bool = True) -> ContactEval:
    """Yarn-yarn contact potential, gradient and Hessian blocks at node positions x (n, 3), mm."""
    x = _positions(x, int(stencil.nodes.max()) + 1 if len(stencil) else None)
    gap = pair_gaps(x, stencil)
    idx = np.flatnonzero(gap < enforcement.cutoff).astype(np.int64)
    na = len(idx)
    e = np.zeros(na)
    lam_a = np.zeros(na)
    g = np.zeros((na, 12))
    H = np.zeros((na, 12, 12)) if hessian else np.zeros((0, 12, 12))
    c0, c1 = enforcement.pair_c_range(stencil)
    if na:
        args = (x, stencil.nodes, stencil.shift, stencil.rsum, stencil.alpha, stencil.beta, idx,
                enforcement.code, enforcement.params, enforcement.cutoff, c0, c1, hessian,
                bool(enforcement.project))
        if _parallel(na, "eval"):
            _pair_eval_par(*args, _chunks(na), e, lam_a, g, H)
        else:
            _pair_eval_ser(*args, e, lam_a, g, H)
    grad = np.zeros_like(x)
    energy = float(e.sum())
    if np.isfinite(energy):
        _scatter(stencil.nodes, idx, g, grad)
    lam = np.zeros(len(stencil))
    lam[idx] = lam_a
    return ContactEval(energy=energy, grad=grad, gap=gap, lam=lam, active=idx,
                       hess=H if hessian else None, hess_nodes=stencil.nodes[idx])


# ----------------------------------------------------------------------------------------
def assemble_blocks(blocks, block_nodes, n_nodes: int, dof_per_node: int = 3) -> sp.csr_matrix:
    """Scatter (na, 3s, 3s) blocks over (na, s) nodes into a sparse (N, N) CSR matrix.

    ``dof_per_node`` 3 (translations only) or 6 (the frame's DOFs: translations 6 i + 0..2).
    Repeated nodes (periodic images of one node) add up.
    """
    blocks = np.asarray(blocks, dtype=float)
    nd = np.asarray(block_nodes, dtype=np.int64)
    na, s = nd.shape if nd.ndim == 2 else (0, 1)
    N = dof_per_node * n_nodes
    if na == 0:
        return sp.csr_matrix((N, N))
    dof = (dof_per_node * nd[:, :, None] + np.arange(3)).reshape(na, 3 * s)
    rows = np.broadcast_to(dof[:, :, None], blocks.shape).ravel()
    cols = np.broadcast_to(dof[:, None, :], blocks.shape).ravel()
    return sp.csr_matrix((blocks.ravel(), (rows, cols)), shape=(N, N))
