"""Distances for large-motion contact: segment-segment, point-segment, point-point, point-plane.

All distances are *squared* centre-line distances (mm^2) with exact first and second
derivatives of the closest-point case that is active (the approach of IPC, Li et al. 2020):

* two segments (a0, a1), (b0, b1): nine cases, numbered as ``ipctk.EdgeEdgeDistanceType``
  (0 EA0_EB0, 1 EA0_EB1, 2 EA1_EB0, 3 EA1_EB1, 4 EA_EB0, 5 EA_EB1, 6 EA0_EB, 7 EA1_EB,
  8 EA_EB: "EA" = interior of segment a, "EA0" = its end a0, ...);
* a point p and a segment (e0, e1): three cases as ``ipctk.PointEdgeDistanceType``
  (0 P_E0, 1 P_E1, 2 P_E).

One formula covers every case. Write the points of a four-point *stencil* x = (x0, x1, x2, x3)
= (a0, a1, b0, b1) and D(s, t) = (1 - s) x0 + s x1 - (1 - t) x2 - t x3, F = |D|^2. A case fixes
each parameter at 0 or 1 or leaves it free, and its distance is the minimum of F over the
free ones. By the envelope theorem its gradient is dF/dx at the optimum and its Hessian is
the Schur complement ``F_xx - F_xy F_yy^-1 F_yx`` over the free parameters y: exact,
symmetric, and the same arithmetic for the line-line (both free), point-line (one free) and
point-point (none free) formulas. A point-segment distance is the stencil (p, p, e0, e1)
with s fixed at 0.

The squared distance is C1 in the positions wherever its closest points are unique (the
Hessian jumps where the case changes). Exactly parallel segments have a whole interval of
closest points and a kink; :mod:`homtex.contact.potential` blends near-parallel pairs into
point-segment terms so that the contact energy stays smooth there. ``sin2_angle`` (with
derivatives) measures how parallel two segments are.

Array arguments are float64; the stencil is a (4, 3) array, gradients (12,), Hessians
(12, 12), ordered (x0, y0, z0, x1, ...) point by point.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..errors import InputError
from .narrow import _clamp01

# ipctk's EdgeEdgeDistanceType numbering, indexed by the (s, t) state: 0 = fixed at 0,
# 1 = fixed at 1, 2 = free.  CASE_EE[s_state, t_state]
CASE_EE = np.array([[0, 1, 6], [2, 3, 7], [4, 5, 8]], dtype=np.int64)
EE_CASE_NAMES = ("EA0_EB0", "EA0_EB1", "EA1_EB0", "EA1_EB1", "EA_EB0", "EA_EB1", "EA0_EB", "EA1_EB",
                 "EA_EB")
PE_CASE_NAMES = ("P_E0", "P_E1", "P_E")
# relative threshold on |ea x eb|^2 / (|ea|^2 |eb|^2) below which the line-line formula is not
# tried (the closest points of exactly parallel segments are found on the boundary)
PARALLEL_EPS = 1e-12


@njit(cache=True)
def _stencil_d2(P, s, t, free_s, free_t, g, H, hess):
    """Squared distance |D(s, t)|^2 of stencil P (4, 3) with its derivatives.

    ``s``, ``t`` are the case's parameters (the optimum for free ones); ``free_s``, ``free_t``
    say which are minimised over. Writes the gradient into ``g`` (12,) and, when ``hess``,
    the Hessian into ``H`` (12, 12). Returns the squared distance.
    """
    c0 = 1.0 - s
    c1 = s
    c2 = -(1.0 - t)
    c3 = -t
    dx = c0 * P[0, 0] + c1 * P[1, 0] + c2 * P[2, 0] + c3 * P[3, 0]
    dy = c0 * P[0, 1] + c1 * P[1, 1] + c2 * P[2, 1] + c3 * P[3, 1]
    dz = c0 * P[0, 2] + c1 * P[1, 2] + c2 * P[2, 2] + c3 * P[3, 2]
    cc = (c0, c1, c2, c3)
    for k in range(4):
        g[3 * k] = 2.0 * cc[k] * dx
        g[3 * k + 1] = 2.0 * cc[k] * dy
        g[3 * k + 2] = 2.0 * cc[k] * dz
    if hess:
        for k in range(4):
            for m in range(4):
                v = 2.0 * cc[k] * cc[m]
                for i in range(3):
                    for j in range(3):
                        H[3 * k + i, 3 * m + j] = v if i == j else 0.0
        if free_s or free_t:
            D = (dx, dy, dz)
            ea = (P[1, 0] - P[0, 0], P[1, 1] - P[0, 1], P[1, 2] - P[0, 2])
            eb = (P[3, 0] - P[2, 0], P[3, 1] - P[2, 1], P[3, 2] - P[2, 2])
            dcs = (-1.0, 1.0, 0.0, 0.0)
            dct = (0.0, 0.0, 1.0, -1.0)
            Fss = 2.0 * (ea[0] * ea[0] + ea[1] * ea[1] + ea[2] * ea[2])
            Ftt = 2.0 * (eb[0] * eb[0] + eb[1] * eb[1] + eb[2] * eb[2])
            Fst = -2.0 * (ea[0] * eb[0] + ea[1] * eb[1] + ea[2] * eb[2])
            cs = np.empty(12)
            ct = np.empty(12)
            for k in range(4):
                for i in range(3):
                    cs[3 * k + i] = 2.0 * dcs[k] * D[i] + 2.0 * cc[k] * ea[i]
                    ct[3 * k + i] = 2.0 * dct[k] * D[i] - 2.0 * cc[k] * eb[i]
            if free_s and free_t:
                det = Fss * Ftt - Fst * Fst
                for i in range(12):
                    for j in range(12):
                        H[i, j] -= (Ftt * cs[i] * cs[j] - Fst * (cs[i] * ct[j] + ct[i] * cs[j])
                                    + Fss * ct[i] * ct[j]) / det
            elif free_s:
                for i in range(12):
                    for j in range(12):
                        H[i, j] -= cs[i] * cs[j] / Fss
            else:
                for i in range(12):
                    for j in range(12):
                        H[i, j] -= ct[i] * ct[j] / Ftt
    return dx * dx + dy * dy + dz * dz


@njit(cache=True, inline="always")
def _d2_at(P, s, t):
    c0 = 1.0 - s
    c2 = -(1.0 - t)
    dx = c0 * P[0, 0] + s * P[1, 0] + c2 * P[2, 0] - t * P[3, 0]
    dy = c0 * P[0, 1] + s * P[1, 1] + c2 * P[2, 1] - t * P[3, 1]
    dz = c0 * P[0, 2] + s * P[1, 2] + c2 * P[2, 2] - t * P[3, 2]
    return dx * dx + dy * dy + dz * dz


@njit(cache=True, inline="always")
def _state(par):
    """Parameter state after clamping: 0 fixed at 0, 1 fixed at 1, 2 free (interior)."""
    if par <= 0.0:
        return 0
    if par >= 1.0:
        return 1
    return 2


@njit(cache=True)
def _pe_param(P, end_a, which):
    """Clamped parameter of a point-segment term of stencil P.

    ``end_a`` True: the point is P[which] (an end of a, which in {0, 1}) against segment b,
    returns t. False: the point is P[2 + which] against segment a, returns s.
    """
    if end_a:
        e0 = P[2]
        e1 = P[3]
        p = P[which]
    else:
        e0 = P[0]
        e1 = P[1]
        p = P[2 + which]
    ex = e1[0] - e0[0]
    ey = e1[1] - e0[1]
    ez = e1[2] - e0[2]
    ee = ex * ex + ey * ey + ez * ez
    if ee <= 0.0:
        return 0.0
    return _clamp01(((p[0] - e0[0]) * ex + (p[1] - e0[1]) * ey + (p[2] - e0[2]) * ez) / ee)


@njit(cache=True)
def _ee_classify(P):
    """Closest points of segments P[0]-P[1] and P[2]-P[3]: (d2, s, t, case)."""
    eax = P[1, 0] - P[0, 0]
    eay = P[1, 1] - P[0, 1]
    eaz = P[1, 2] - P[0, 2]
    ebx = P[3, 0] - P[2, 0]
    eby = P[3, 1] - P[2, 1]
    ebz = P[3, 2] - P[2, 2]
    wx = P[0, 0] - P[2, 0]
    wy = P[0, 1] - P[2, 1]
    wz = P[0, 2] - P[2, 2]
    A = eax * eax + eay * eay + eaz * eaz
    B = eax * ebx + eay * eby + eaz * ebz
    C = ebx * ebx + eby * eby + ebz * ebz
    dd = eax * wx + eay * wy + eaz * wz
    e = ebx * wx + eby * wy + ebz * wz
    den = A * C - B * B
    if den > PARALLEL_EPS * A * C:
        s = (B * e - C * dd) / den
        t = (A * e - B * dd) / den
        if 0.0 < s < 1.0 and 0.0 < t < 1.0:
            return _d2_at(P, s, t), s, t, 8
    # the minimum lies on the boundary of the parameter square: best of its four sides
    best = np.inf
    bs = 0.0
    bt = 0.0
    for side in range(4):
        if side == 0:
            s = 0.0
            t = _clamp01(e / C)
        elif side == 1:
            s = 1.0
            t = _clamp01((e + B) / C)
        elif side == 2:
            t = 0.0
            s = _clamp01(-dd / A)
        else:
            t = 1.0
            s = _clamp01((B - dd) / A)
        d2 = _d2_at(P, s, t)
        if d2 < best:
            best = d2
            bs = s
            bt = t
    return best, bs, bt, CASE_EE[_state(bs), _state(bt)]


@njit(cache=True)
def _ee_d2(P):
    """Squared segment-segment distance of stencil P (values only)."""
    d2, s, t, case = _ee_classify(P)
    return d2


@njit(cache=True)
def _ee_distance(P, g, H, hess):
    """Squared segment-segment distance with derivatives of the active case; returns (d2, case)."""
    d2, s, t, case = _ee_classify(P)
    free_s = case == 4 or case == 5 or case == 8
    free_t = case == 6 or case == 7 or case == 8
    return _stencil_d2(P, s, t, free_s, free_t, g, H, hess), case


@njit(cache=True)
def _sin2_angle(P, g, H, deriv):
    """c = |ea x eb|^2 / (|ea|^2 |eb|^2) = sin^2 of the angle between the segments.

    deriv 0: value only; 1: gradient into g (12,); 2: also the Hessian into H (12, 12).
    """
    ea = np.empty(3)
    eb = np.empty(3)
    for i in range(3):
        ea[i] = P[1, i] - P[0, i]
        eb[i] = P[3, i] - P[2, i]
    A = ea[0] * ea[0] + ea[1] * ea[1] + ea[2] * ea[2]
    B = eb[0] * eb[0] + eb[1] * eb[1] + eb[2] * eb[2]
    u = ea[0] * eb[0] + ea[1] * eb[1] + ea[2] * eb[2]
    c = 1.0 - u * u / (A * B)
    if deriv == 0:
        return c
    # h = u^2 / (A B); c = 1 - h.  dh/dea = al * va, dh/deb = al * vb
    al = 2.0 * u / (A * B)
    va = np.empty(3)
    vb = np.empty(3)
    for i in range(3):
        va[i] = eb[i] - (u / A) * ea[i]
        vb[i] = ea[i] - (u / B) * eb[i]
    ga = np.empty(3)
    gb = np.empty(3)
    for i in range(3):
        ga[i] = -al * va[i]
        gb[i] = -al * vb[i]
    for i in range(3):
        g[i] = -ga[i]
        g[3 + i] = ga[i]
        g[6 + i] = -gb[i]
        g[9 + i] = gb[i]
    if deriv == 1:
        return c
    # second derivatives of h in (ea, eb)
    dal_a = np.empty(3)
    dal_b = np.empty(3)
    for i in range(3):
        dal_a[i] = (2.0 / (A * B)) * (eb[i] - 2.0 * u * ea[i] / A)
        dal_b[i] = (2.0 / (A * B)) * (ea[i] - 2.0 * u * eb[i] / B)
    Haa = np.empty((3, 3))
    Hab = np.empty((3, 3))
    Hbb = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            dij = 1.0 if i == j else 0.0
            dva = -ea[i] * eb[j] / A - (u / A) * dij + 2.0 * u * ea[i] * ea[j] / (A * A)   # dva_i/dea_j
            dvb = -eb[i] * ea[j] / B - (u / B) * dij + 2.0 * u * eb[i] * eb[j] / (B * B)   # dvb_i/deb_j
            Haa[i, j] = va[i] * dal_a[j] + al * dva
            Hbb[i, j] = vb[i] * dal_b[j] + al * dvb
            Hab[i, j] = va[i] * dal_b[j] + al * (dij - ea[i] * ea[j] / A)                # d(al va_i)/deb_j
    # ea = x1 - x0, eb = x3 - x2: signs (-1, +1) per segment; c = 1 - h
    sg = (-1.0, 1.0)
    for p in range(2):
        for q in range(2):
            for i in range(3):
                for j in range(3):
                    H[3 * p + i, 3 * q + j] = -sg[p] * sg[q] * Haa[i, j]
                    H[6 + 3 * p + i, 6 + 3 * q + j] = -sg[p] * sg[q] * Hbb[i, j]
                    H[3 * p + i, 6 + 3 * q + j] = -sg[p] * sg[q] * Hab[i, j]
                    H[6 + 3 * q + j, 3 * p + i] = -sg[p] * sg[q] * Hab[i, j]
    return c


# ----------------------------------------------------------------------------------------
# public wrappers (checked inputs, one configuration at a time: tests, scripts, small uses)
def _point(v, name):
    a = np.asarray(v, dtype=float)
    if a.shape != (3,):
        raise InputError(f"{name} must be a 3-vector (mm), got shape {a.shape}")
    if not np.isfinite(a).all():
        raise InputError(f"{name} must be finite, got {a.tolist()}")
    return a


def _segment(p0, p1, name):
    a = _point(p0, f"{name}0")
    b = _point(p1, f"{name}1")
    if not np.any(b != a):
        raise InputError(f"segment {name} has zero length ({name}0 == {name}1 = {a.tolist()})")
    return a, b


def segment_distance(a0, a1, b0, b1, hessian: bool = True) -> tuple:
    """Squared distance between segments (a0, a1) and (b0, b1), with exact derivatives.

    Parameters
    ----------
    a0, a1, b0, b1 : (3,) end points, mm.
    hessian : also return the Hessian.

    Returns
    -------
    (d2, grad, hess, case): d2 squared distance (mm^2); grad (12,) w.r.t. (a0, a1, b0, b1);
    hess (12, 12) or None; case the active closest-point case (``ipctk.EdgeEdgeDistanceType``
    numbering, names in ``EE_CASE_NAMES``).
    """
    a0, a1 = _segment(a0, a1, "a")
    b0, b1 = _segment(b0, b1, "b")
    P = np.ascontiguousarray(np.stack([a0, a1, b0, b1]))
    g = np.zeros(12)
    H = np.zeros((12, 12))
    d2, case = _ee_distance(P, g, H, hessian)
    return float(d2), g, (H if hessian else None), int(case)


def point_segment_distance(p, e0, e1, hessian: bool = True) -> tuple:
    """Squared distance between point p and segment (e0, e1), with exact derivatives.

    Returns (d2, grad (9,) w.r.t. (p, e0, e1), hess (9, 9) or None, case) with the case
    numbered as ``ipctk.PointEdgeDistanceType`` (0 P_E0, 1 P_E1, 2 P_E).
    """
    p = _point(p, "p")
    e0, e1 = _segment(e0, e1, "e")
    P = np.ascontiguousarray(np.stack([p, p, e0, e1]))
    t = _pe_param(P, True, 0)
    st = _state(t)
    g = np.zeros(12)
    H = np.zeros((12, 12))
    d2 = _stencil_d2(P, 0.0, t, False, st == 2, g, H, hessian)
    keep = np.r_[0:3, 6:12]
    return float(d2), g[keep], (H[np.ix_(keep, keep)] if hessian else None), int(st)


def point_point_distance(p, q) -> tuple:
    """Squared distance |p - q|^2 (mm^2), its gradient (6,) and Hessian (6, 6)."""
    p = _point(p, "p")
    q = _point(q, "q")
    d = p - q
    I3 = np.eye(3)
    return float(d @ d), np.concatenate([2 * d, -2 * d]), 2.0 * np.block([[I3, -I3], [-I3, I3]])


def point_plane_gap(p, origin, normal, radius: float = 0.0) -> tuple:
    """Gap between a sphere of ``radius`` at p and the plane through ``origin`` with ``normal``.

    g = n . (p - origin) - radius (mm), n = normal / |normal| pointing to the side where the
    yarns belong (g < 0: the node's section crosses the plane). Returns (g, grad (3,)); the
    Hessian w.r.t. p is zero.
    """
    p = _point(p, "p")
    o = _point(origin, "origin")
    n = _point(normal, "normal")
    nn = float(np.linalg.norm(n))
    if nn == 0.0:
        raise InputError("normal must be a non-zero 3-vector")
    r = float(radius)
    if not (np.isfinite(r) and r >= 0.0):
        raise InputError(f"radius must be finite and >= 0 (mm), got {radius!r}")
    n = n / nn
    return float(n @ (p - o) - r), n


def sin2_angle(a0, a1, b0, b1, hessian: bool = True) -> tuple:
    """c = sin^2 of the angle between segments a and b (|ea x eb|^2 / (|ea|^2 |eb|^2)).

    Returns (c, grad (12,), hess (12, 12) or None); the measure of parallelism used by the
    near-parallel blend of :mod:`homtex.contact.potential`.
    """
    a0, a1 = _segment(a0, a1, "a")
    b0, b1 = _segment(b0, b1, "b")
    P = np.ascontiguousarray(np.stack([a0, a1, b0, b1]))
    g = np.zeros(12)
    H = np.zeros((12, 12))
    c = _sin2_angle(P, g, H, 2 if hessian else 1)
    return float(c), g, (H if hessian else None)
