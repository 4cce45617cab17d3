"""Co-rotational 3D beam kernels: large rotations, small strains, consistent tangent.

Each element carries a frame that follows it (the *co-rotated* frame Er, columns r1, r2, r3):
r1 along the current chord, r3 = r1 x p / |r1 x p| with p the mean of the two rotated end axes
e2, r2 = r3 x r1 (the element-independent co-rotational frame of Battini and Pacoste 2002). In Er
the element is the linear Timoshenko beam of :mod:`homtex.fem.beam`, loaded only by its stretch
l - l0 and its end *deformational* rotations theta_a = log(Er^T Q_a E0^T) (Q_a: rotation of node a
from the start, E0: the end's rest frame: the initial element frame when the start geometry is
stress-free, else the frame a rest state gives it, :mod:`homtex.model.rest`; l0 the rest length).
Rigid motions of any size leave l - l0 and theta unchanged, so they give exactly zero force;
rotations within an element must stay moderate (a few tenths of a radian), which mesh refinement
ensures.

Internal forces are the exact gradient of the element energy
U = EA l0 / 2 ((l - l0) / l0 + eps0)^2 + 1/2 theta . K_theta theta
with respect to nodal translations and nodal spatial spins (delta Q_a = spin(dw_a) Q_a):

    f_x(j) = -f_x(i) = v = N r1 + ((eta s1 + s2) / l) r3 - (s3 / l) r2
    f_w(a) = G_a - (s1 / 2s) (t_a x r3),    G_a = Er T^-T(theta_a) m_a,  S = G_i + G_j,

with s = |r1 x p|, s_k = S . r_k, eta = (p . r1) / s, t_a the rotated e2 axis of end a and
T^-1(theta) = I - 1/2 [theta] + eta(|theta|) [theta]^2 the inverse tangent map of the rotation
vector. The *consistent tangent* K = d f / d(x, w) is its exact derivative, obtained by carrying
3 x 12 Jacobians of every intermediate quantity through the same formulas (hand-written forward
mode; :func:`element_kernel`). Its symmetric part is the Hessian of U (exponential-map charts);
its skew part is -1/2 [m]x on each node's rotation block (m: the node's internal moment), so at
equilibrium without applied moments K is symmetric (tests check K against central differences of
the forces and this structure).

Units: mm, N, MPa; arrays as in :mod:`homtex.fem.beam`.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from .beam import coefficients, end_energy

#: 3 x 12 Jacobian slots in the per-element workspace (see :func:`element_kernel`)
_NW = 23
_NV = 18
_NM = 8


@njit(cache=True)
def expmap(v):
    """Rotation matrix (3, 3) of a rotation vector v (3,) (Rodrigues)."""
    th2 = v[0] * v[0] + v[1] * v[1] + v[2] * v[2]
    th = np.sqrt(th2)
    if th < 1e-8:
        a = 1.0 - th2 / 6.0
        b = 0.5 - th2 / 24.0
    else:
        a = np.sin(th) / th
        b = (1.0 - np.cos(th)) / th2
    K = np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
    return np.eye(3) + a * K + b * (K @ K)


@njit(cache=True)
def logmap(R):
    """Rotation vector (3,) of a rotation matrix (angle < pi), via the quaternion (robust near 0);
    :func:`_logmap_into` without an output array."""
    out = np.empty(3)
    _logmap_into(R, out)
    return out


@njit(cache=True, inline="always")
def _eta_mu(t2):
    """eta(t) = (1 - (t/2) cot(t/2)) / t^2 and mu = eta'(t) / t for t^2 = |theta|^2."""
    if t2 < 2.5e-3:                 # series (t < 0.05): the closed forms cancel
        eta = 1.0 / 12.0 + t2 / 720.0 + t2 * t2 / 30240.0 + t2 * t2 * t2 / 1209600.0
        mu = 1.0 / 360.0 + t2 / 7560.0 + t2 * t2 / 201600.0
        return eta, mu
    t = np.sqrt(t2)
    c = 0.5 * t / np.tan(0.5 * t)
    eta = (1.0 - c) / t2
    sh = np.sin(0.5 * t)
    dc = 0.5 / np.tan(0.5 * t) - 0.25 * t / (sh * sh)
    mu = (-dc * t - 2.0 * (1.0 - c)) / (t2 * t2)
    return eta, mu


# ---------------------------------------------------------------------------------------------
# small dense helpers on 3 x 12 Jacobians (columns: x_i, w_i, x_j, w_j)
@njit(cache=True, inline="always")
def _cross_jac(a, M, out, scale):
    """out (3, 12) += scale * (a x M[:, k]) for every column k."""
    for k in range(12):
        out[0, k] += scale * (a[1] * M[2, k] - a[2] * M[1, k])
        out[1, k] += scale * (a[2] * M[0, k] - a[0] * M[2, k])
        out[2, k] += scale * (a[0] * M[1, k] - a[1] * M[0, k])


@njit(cache=True, inline="always")
def _dot_jac(a, M, out, scale):
    """out (12,) += scale * a^T M."""
    for k in range(12):
        out[k] += scale * (a[0] * M[0, k] + a[1] * M[1, k] + a[2] * M[2, k])


@njit(cache=True, inline="always")
def _mat_jac(A, M, out, scale):
    """out (3, 12) += scale * A (3, 3) @ M (3, 12)."""
    for r in range(3):
        for k in range(12):
            out[r, k] += scale * (A[r, 0] * M[0, k] + A[r, 1] * M[1, k] + A[r, 2] * M[2, k])


@njit(cache=True, inline="always")
def _outer_jac(a, row, out, scale):
    """out (3, 12) += scale * a row^T."""
    for r in range(3):
        for k in range(12):
            out[r, k] += scale * a[r] * row[k]


@njit(cache=True, inline="always")
def _spin_block(a, out, col, scale):
    """out[:, col:col+3] += scale * [a]x."""
    out[0, col + 1] -= scale * a[2]
    out[0, col + 2] += scale * a[1]
    out[1, col + 0] += scale * a[2]
    out[1, col + 2] -= scale * a[0]
    out[2, col + 0] -= scale * a[1]
    out[2, col + 1] += scale * a[0]


@njit(cache=True, inline="always")
def _cross3(a, b, out):
    out[0] = a[1] * b[2] - a[2] * b[1]
    out[1] = a[2] * b[0] - a[0] * b[2]
    out[2] = a[0] * b[1] - a[1] * b[0]


@njit(cache=True, inline="always")
def _dot3(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@njit(cache=True, inline="always")
def _logmap_into(R, out):
    """out (3,) = log R: the quaternion (direct formula below 120 degrees, else Shepperd's largest
    diagonal), then the angle from atan2 (robust near 0)."""
    tr = R[0, 0] + R[1, 1] + R[2, 2]
    q0 = 0.5 * np.sqrt(max(1.0 + tr, 0.0))
    if q0 > 0.5:
        f = 0.25 / q0
        x = (R[2, 1] - R[1, 2]) * f
        y = (R[0, 2] - R[2, 0]) * f
        z = (R[1, 0] - R[0, 1]) * f
    else:
        k = 0
        if R[1, 1] > R[k, k]:
            k = 1
        if R[2, 2] > R[k, k]:
            k = 2
        i, j = (k + 1) % 3, (k + 2) % 3
        qk = 0.5 * np.sqrt(max(1.0 + R[k, k] - R[i, i] - R[j, j], 1e-300))
        f = 0.25 / qk
        out[k] = qk
        out[i] = (R[i, k] + R[k, i]) * f
        out[j] = (R[j, k] + R[k, j]) * f
        q0 = (R[j, i] - R[i, j]) * f
        if q0 < 0.0:
            q0 = -q0
            out[0] = -out[0]
            out[1] = -out[1]
            out[2] = -out[2]
        x, y, z = out[0], out[1], out[2]
    sn = np.sqrt(x * x + y * y + z * z)
    g = 2.0 / q0 if sn < 1e-12 else 2.0 * np.arctan2(sn, q0) / sn
    out[0] = g * x
    out[1] = g * y
    out[2] = g * z


@njit(cache=True, inline="always")
def _tinv_into(th, T):
    """T (3, 3) = T^-1(theta) = I - 1/2 [theta] + eta [theta]^2; returns (eta, mu)."""
    t2 = th[0] * th[0] + th[1] * th[1] + th[2] * th[2]
    eta, mu = _eta_mu(t2)
    for r in range(3):
        for c in range(3):
            T[r, c] = (1.0 - eta * t2 if r == c else 0.0) + eta * th[r] * th[c]
    T[0, 1] += 0.5 * th[2]
    T[0, 2] -= 0.5 * th[1]
    T[1, 0] -= 0.5 * th[2]
    T[1, 2] += 0.5 * th[0]
    T[2, 0] += 0.5 * th[1]
    T[2, 1] -= 0.5 * th[0]
    return eta, mu


@njit(cache=True, inline="always")
def _dtinv_t_into(th, m, eta, mu, D):
    """D (3, 3) = d (T^-T(theta) m) / d theta at fixed m."""
    tm = th[0] * m[0] + th[1] * m[1] + th[2] * m[2]
    tt = th[0] * th[0] + th[1] * th[1] + th[2] * th[2]
    for r in range(3):
        br = th[r] * tm - m[r] * tt                     # theta x (theta x m)
        for c in range(3):
            D[r, c] = eta * ((tm if r == c else 0.0) + th[r] * m[c] - 2.0 * m[r] * th[c]) + mu * br * th[c]
    D[0, 1] += 0.5 * m[2]
    D[0, 2] -= 0.5 * m[1]
    D[1, 0] -= 0.5 * m[2]
    D[1, 2] += 0.5 * m[0]
    D[2, 0] += 0.5 * m[1]
    D[2, 1] -= 0.5 * m[0]


@njit(cache=True, inline="always")
def _mat_jac_t(A, M, out, scale):
    """out (3, 12) += scale * A^T (3, 3) @ M (3, 12)."""
    for r in range(3):
        for k in range(12):
            out[r, k] += scale * (A[0, r] * M[0, k] + A[1, r] * M[1, k] + A[2, r] * M[2, k])


@njit(cache=True)
def element_kernel(xi, xj, Qi, Qj, E0i, E0j, L0, EA, GJ, EIy, EIz, kGA, eps0,
                   fe, Ke, fl, Er, th, ws, vs, ms, want_tangent):
    """Internal forces (and the consistent tangent) of one co-rotational element.

    Parameters
    ----------
    xi, xj : (3,) current end positions (xj with the periodic shift), mm.
    Qi, Qj : (3, 3) nodal rotations. E0i, E0j : (3, 3) rest frames of the two ends (rows e1, e2,
        e3): the end is stress-free when Q E0^T equals the co-rotated frame (both the element's
        initial frame when the start geometry is the rest state; see :mod:`homtex.model.rest`).
    L0 : rest length, mm.
    fe : out (2, 6) forces/moments on the two nodes (internal force vector), N, N mm.
    Ke : out (12, 12) d fe / d(x_i, w_i, x_j, w_j) (spatial spins), if ``want_tangent``.
    fl : out (12,) local end forces in Er. Er : out (3, 3) rows r1, r2, r3.
    th : out (2, 3) deformational end rotations, rad.
    ws, vs, ms : scratch (_NW, 3, 12), (_NV, 3), (_NM, 3, 3) (no allocation per element).

    Returns the current length l (mm).
    """
    r1, r2, r3, p, c, ti, tj = vs[0], vs[1], vs[2], vs[3], vs[4], vs[5], vs[6]
    thi, thj, gi, gj, Gi, Gj, S, wi, wj = vs[7], vs[8], vs[9], vs[10], vs[11], vs[12], vs[13], vs[14], vs[15]
    mi, mj = vs[16], vs[17]
    R, Ti, Tj, Rd, Tinv_i, Tinv_j = ms[0], ms[1], ms[2], ms[3], ms[4], ms[5]
    for a in range(3):
        r1[a] = xj[a] - xi[a]
    l = np.sqrt(_dot3(r1, r1))
    for a in range(3):
        r1[a] /= l
    # rotated initial axes: T = Q E0^T (columns)
    for a in range(3):
        for b in range(3):
            Ti[a, b] = Qi[a, 0] * E0i[b, 0] + Qi[a, 1] * E0i[b, 1] + Qi[a, 2] * E0i[b, 2]
            Tj[a, b] = Qj[a, 0] * E0j[b, 0] + Qj[a, 1] * E0j[b, 1] + Qj[a, 2] * E0j[b, 2]
    for a in range(3):
        ti[a] = Ti[a, 1]
        tj[a] = Tj[a, 1]
        p[a] = 0.5 * (ti[a] + tj[a])
    _cross3(r1, p, c)
    s = np.sqrt(_dot3(c, c))
    for a in range(3):
        r3[a] = c[a] / s
    _cross3(r3, r1, r2)
    for a in range(3):
        R[a, 0] = r1[a]
        R[a, 1] = r2[a]
        R[a, 2] = r3[a]
    for side in range(2):
        T = Ti if side == 0 else Tj
        for a in range(3):
            for b in range(3):
                Rd[a, b] = R[0, a] * T[0, b] + R[1, a] * T[1, b] + R[2, a] * T[2, b]
        _logmap_into(Rd, thi if side == 0 else thj)
    ax, tor, a_y, b_y, c_y, d_y, a_z, b_z, c_z, d_z = coefficients(L0, EA, GJ, EIy, EIz, kGA)
    # local forces of the linear element for d = (0, 0, 0, thi, l - L0, 0, 0, thj)
    N = ax * (l - L0) + EA * eps0
    T_ = tor * (thj[0] - thi[0])
    fz1 = c_y * thi[2] + d_y * thj[2]
    fz2 = d_y * thi[2] + c_y * thj[2]
    fv1 = b_y * (thi[2] + thj[2])
    fy1 = c_z * thi[1] + d_z * thj[1]
    fy2 = d_z * thi[1] + c_z * thj[1]
    fw1 = -b_z * (thi[1] + thj[1])
    fl[0] = -N
    fl[1] = fv1
    fl[2] = fw1
    fl[3] = -T_
    fl[4] = fy1
    fl[5] = fz1
    fl[6] = N
    fl[7] = -fv1
    fl[8] = -fw1
    fl[9] = T_
    fl[10] = fy2
    fl[11] = fz2
    mi[0], mi[1], mi[2] = -T_, fy1, fz1
    mj[0], mj[1], mj[2] = T_, fy2, fz2
    eta_i, mu_i = _tinv_into(thi, Tinv_i)
    eta_j, mu_j = _tinv_into(thj, Tinv_j)
    for a in range(3):
        gi[a] = Tinv_i[0, a] * mi[0] + Tinv_i[1, a] * mi[1] + Tinv_i[2, a] * mi[2]
        gj[a] = Tinv_j[0, a] * mj[0] + Tinv_j[1, a] * mj[1] + Tinv_j[2, a] * mj[2]
    for a in range(3):
        Gi[a] = R[a, 0] * gi[0] + R[a, 1] * gi[1] + R[a, 2] * gi[2]
        Gj[a] = R[a, 0] * gj[0] + R[a, 1] * gj[1] + R[a, 2] * gj[2]
        S[a] = Gi[a] + Gj[a]
    s1 = _dot3(S, r1)
    s2 = _dot3(S, r2)
    s3 = _dot3(S, r3)
    p1 = _dot3(p, r1)
    eta = p1 / s
    alpha = (eta * s1 + s2) / l
    beta = s3 / l
    h = s1 / (2.0 * s)
    _cross3(ti, r3, wi)
    _cross3(tj, r3, wj)
    for a in range(3):
        v = N * r1[a] + alpha * r3[a] - beta * r2[a]
        fe[0, a] = -v
        fe[1, a] = v
        fe[0, 3 + a] = Gi[a] - h * wi[a]
        fe[1, 3 + a] = Gj[a] - h * wj[a]
        Er[0, a] = r1[a]
        Er[1, a] = r2[a]
        Er[2, a] = r3[a]
        th[0, a] = thi[a]
        th[1, a] = thj[a]
    if want_tangent:
        _element_tangent(ws, ms, Ke, l, r1, r2, r3, R, p, s, ti, tj, thi, thj, Tinv_i, Tinv_j, eta_i, mu_i,
                         eta_j, mu_j, mi, mj, gi, gj, S, s1, s2, s3, p1, eta, alpha, beta, N, h, wi, wj,
                         ax, tor, c_y, d_y, c_z, d_z)
    return l


@njit(cache=True)
def _element_tangent(ws, ms, Ke, l, r1, r2, r3, R, p, s, ti, tj, thi, thj, Tinv_i, Tinv_j, eta_i, mu_i,
                     eta_j, mu_j, mi, mj, gi, gj, S, s1, s2, s3, p1, eta, alpha, beta, N, h, wi, wj,
                     ax, tor, c_y, d_y, c_z, d_z):
    """Ke (12, 12) = exact derivative of the forces of :func:`element_kernel` (forward mode)."""
    ws[:] = 0.0
    dr1, dp, dc, dr3, dr2, dwr = ws[0], ws[1], ws[2], ws[3], ws[4], ws[5]
    dthi, dthj, Y, dmi, dmj, dgi, dgj = ws[6], ws[7], ws[8], ws[9], ws[10], ws[11], ws[12]
    dS, dv, dwi, dwj, dti, dtj = ws[13], ws[14], ws[15], ws[16], ws[17], ws[18]
    sc, sc2, sc3, sc4 = ws[19], ws[20], ws[21], ws[22]
    dl, ds, ds1 = sc[0], sc[1], sc[2]
    ds2, ds3, dp1 = sc2[0], sc2[1], sc2[2]
    deta, dal, dbe = sc3[0], sc3[1], sc3[2]
    dh, dN = sc4[0], sc4[1]
    Dm = ms[6]
    inv_l = 1.0 / l
    for a in range(3):
        dl[a] = -r1[a]
        dl[6 + a] = r1[a]
        for b in range(3):
            P = ((1.0 if a == b else 0.0) - r1[a] * r1[b]) * inv_l
            dr1[a, b] = -P
            dr1[a, 6 + b] = P
    # rotated e2 axes turn with their node's spin: d t = -[t]x dw
    _spin_block(ti, dti, 3, -1.0)
    _spin_block(tj, dtj, 9, -1.0)
    for a in range(3):
        for k in range(12):
            dp[a, k] = 0.5 * (dti[a, k] + dtj[a, k])
    # c = r1 x p; r3 = c / s; r2 = r3 x r1
    _cross_jac(r1, dp, dc, 1.0)
    _cross_jac(p, dr1, dc, -1.0)
    _dot_jac(r3, dc, ds, 1.0)
    inv_s = 1.0 / s
    for a in range(3):
        for k in range(12):
            dr3[a, k] = (dc[a, k] - r3[a] * ds[k]) * inv_s
    _cross_jac(r3, dr1, dr2, 1.0)
    _cross_jac(r1, dr3, dr2, -1.0)
    # spin of the co-rotated frame: dw_r = 1/2 sum_k r_k x dr_k
    _cross_jac(r1, dr1, dwr, 0.5)
    _cross_jac(r2, dr2, dwr, 0.5)
    _cross_jac(r3, dr3, dwr, 0.5)
    # d theta_a = T^-1(theta_a) Er^T (dw_a - dw_r)
    for side in range(2):
        Y[:] = 0.0
        _mat_jac_t(R, dwr, Y, -1.0)
        col = 3 if side == 0 else 9
        for a in range(3):
            for b in range(3):
                Y[a, col + b] += R[b, a]
        if side == 0:
            _mat_jac(Tinv_i, Y, dthi, 1.0)
        else:
            _mat_jac(Tinv_j, Y, dthj, 1.0)
    # material part: local forces of the linear element
    for k in range(12):
        dN[k] = ax * dl[k]
        dmi[0, k] = tor * (dthi[0, k] - dthj[0, k])
        dmj[0, k] = -dmi[0, k]
        dmi[1, k] = c_z * dthi[1, k] + d_z * dthj[1, k]
        dmj[1, k] = d_z * dthi[1, k] + c_z * dthj[1, k]
        dmi[2, k] = c_y * dthi[2, k] + d_y * dthj[2, k]
        dmj[2, k] = d_y * dthi[2, k] + c_y * dthj[2, k]
    # g_a = T^-T(theta_a) m_a
    _dtinv_t_into(thi, mi, eta_i, mu_i, Dm)
    _mat_jac(Dm, dthi, dgi, 1.0)
    _mat_jac_t(Tinv_i, dmi, dgi, 1.0)
    _dtinv_t_into(thj, mj, eta_j, mu_j, Dm)
    _mat_jac(Dm, dthj, dgj, 1.0)
    _mat_jac_t(Tinv_j, dmj, dgj, 1.0)
    # S = Er (g_i + g_j): dS = sum_k g_k dr_k + Er dg
    g0, g1, g2 = gi[0] + gj[0], gi[1] + gj[1], gi[2] + gj[2]
    for a in range(3):
        for k in range(12):
            dS[a, k] = g0 * dr1[a, k] + g1 * dr2[a, k] + g2 * dr3[a, k]
    _mat_jac(R, dgi, dS, 1.0)
    _mat_jac(R, dgj, dS, 1.0)
    _dot_jac(r1, dS, ds1, 1.0)
    _dot_jac(S, dr1, ds1, 1.0)
    _dot_jac(r2, dS, ds2, 1.0)
    _dot_jac(S, dr2, ds2, 1.0)
    _dot_jac(r3, dS, ds3, 1.0)
    _dot_jac(S, dr3, ds3, 1.0)
    _dot_jac(r1, dp, dp1, 1.0)
    _dot_jac(p, dr1, dp1, 1.0)
    for k in range(12):
        deta[k] = dp1[k] * inv_s - p1 * ds[k] * inv_s * inv_s
        dal[k] = (s1 * deta[k] + eta * ds1[k] + ds2[k]) * inv_l - alpha * dl[k] * inv_l
        dbe[k] = ds3[k] * inv_l - beta * dl[k] * inv_l
        dh[k] = 0.5 * ds1[k] * inv_s - h * ds[k] * inv_s
    # v = N r1 + alpha r3 - beta r2
    _outer_jac(r1, dN, dv, 1.0)
    _outer_jac(r3, dal, dv, 1.0)
    _outer_jac(r2, dbe, dv, -1.0)
    for a in range(3):
        for k in range(12):
            dv[a, k] += N * dr1[a, k] + alpha * dr3[a, k] - beta * dr2[a, k]
    # w_a = t_a x r3
    _cross_jac(ti, dr3, dwi, 1.0)
    _cross_jac(r3, dti, dwi, -1.0)
    _cross_jac(tj, dr3, dwj, 1.0)
    _cross_jac(r3, dtj, dwj, -1.0)
    # f_w(a) = R g_a + sum_k g_a,k dr_k - h w_a
    for a in range(3):
        for k in range(12):
            Ke[a, k] = -dv[a, k]
            Ke[6 + a, k] = dv[a, k]
            Ke[3 + a, k] = (gi[0] * dr1[a, k] + gi[1] * dr2[a, k] + gi[2] * dr3[a, k]
                            - wi[a] * dh[k] - h * dwi[a, k]
                            + R[a, 0] * dgi[0, k] + R[a, 1] * dgi[1, k] + R[a, 2] * dgi[2, k])
            Ke[9 + a, k] = (gj[0] * dr1[a, k] + gj[1] * dr2[a, k] + gj[2] * dr3[a, k]
                            - wj[a] * dh[k] - h * dwj[a, k]
                            + R[a, 0] * dgj[0, k] + R[a, 1] * dgj[1, k] + R[a, 2] * dgj[2, k])


@njit(cache=True)
def _one_element(e, x, Q, elements, shift, E0, L0, EA, GJ, EIy, EIz, kGA, eps0,
                 fe, Ke, Rr, lcur, theta, forces, energy, ws, vs, ms, want_tangent):
    i = elements[e, 0]
    j = elements[e, 1]
    xj = ms[7, 0]
    for a in range(3):
        xj[a] = x[j, a] + shift[e, a]
    fl = forces[e]
    lcur[e] = element_kernel(x[i], xj, Q[i], Q[j], E0[e, 0], E0[e, 1], L0[e], EA[e], GJ[e], EIy[e], EIz[e],
                             kGA[e], eps0[e], fe[e], Ke[e] if want_tangent else Ke[0], fl, Rr[e], theta[e], ws, vs, ms,
                             want_tangent)
    end_energy(fl, L0[e], EA[e], GJ[e], EIy[e], EIz[e], kGA[e], energy[e])


@njit(cache=True, parallel=True)
def corotational_response(x, Q, elements, shift, E0, L0, EA, GJ, EIy, EIz, kGA, eps0,
                          fe, Rr, lcur, theta, forces, energy):
    """Co-rotational internal forces of every element (no tangent).

    Parameters
    ----------
    x : (n, 3) current node positions, mm. Q : (n, 3, 3) nodal rotations from the start.
    shift : (m, 3) offset of each element's second node (periodic images), mm.
    E0 : (m, 2, 3, 3) rest frames of both ends (rows e1, e2, e3; the initial element frame twice
        when the start geometry is stress-free). L0 : (m,) rest lengths, mm.
    eps0 : (m,) pre-strain (tension positive).
    fe : out (m, 2, 6) forces and moments the element exerts on its two nodes' DOFs
        (internal force vector: the residual is f_ext - sum fe).
    Rr : out (m, 3, 3) co-rotated frames (rows r1, r2, r3). lcur : out (m,) current lengths.
    theta : out (m, 2, 3) end rotations relative to Rr (local axes), rad.
    forces : out (m, 12) local end forces in Rr (as :func:`homtex.fem.beam.element_response`).
    energy : out (m, 5) energy split, N mm.
    """
    m = elements.shape[0]
    Kdummy = np.empty((1, 12, 12))
    nb = (m + 63) // 64
    for b in prange(nb):
        ws = np.empty((_NW, 3, 12))
        vs = np.empty((_NV, 3))
        ms = np.empty((_NM, 3, 3))
        for e in range(64 * b, min(m, 64 * b + 64)):
            _one_element(e, x, Q, elements, shift, E0, L0, EA, GJ, EIy, EIz, kGA, eps0,
                         fe, Kdummy, Rr, lcur, theta, forces, energy, ws, vs, ms, False)


@njit(cache=True, parallel=True)
def corotational_tangent(x, Q, elements, shift, E0, L0, EA, GJ, EIy, EIz, kGA, eps0,
                         fe, Ke, Rr, lcur, theta, forces, energy):
    """As :func:`corotational_response`, plus the element tangents Ke (m, 12, 12) (consistent:
    exact derivative of fe with respect to (x_i, w_i, x_j, w_j), spatial spins)."""
    m = elements.shape[0]
    nb = (m + 63) // 64
    for b in prange(nb):
        ws = np.empty((_NW, 3, 12))
        vs = np.empty((_NV, 3))
        ms = np.empty((_NM, 3, 3))
        for e in range(64 * b, min(m, 64 * b + 64)):
            _one_element(e, x, Q, elements, shift, E0, L0, EA, GJ, EIy, EIz, kGA, eps0,
                         fe, Ke, Rr, lcur, theta, forces, energy, ws, vs, ms, True)


@njit(cache=True)
def corotational_response_serial(x, Q, elements, shift, E0, L0, EA, GJ, EIy, EIz, kGA, eps0,
                                 fe, Rr, lcur, theta, forces, energy):
    """:func:`corotational_response` on one thread."""
    Kdummy = np.empty((1, 12, 12))
    ws = np.empty((_NW, 3, 12))
    vs = np.empty((_NV, 3))
    ms = np.empty((_NM, 3, 3))
    for e in range(elements.shape[0]):
        _one_element(e, x, Q, elements, shift, E0, L0, EA, GJ, EIy, EIz, kGA, eps0,
                     fe, Kdummy, Rr, lcur, theta, forces, energy, ws, vs, ms, False)


@njit(cache=True)
def corotational_tangent_serial(x, Q, elements, shift, E0, L0, EA, GJ, EIy, EIz, kGA, eps0,
                                fe, Ke, Rr, lcur, theta, forces, energy):
    """:func:`corotational_tangent` on one thread (small frames: no thread start-up)."""
    ws = np.empty((_NW, 3, 12))
    vs = np.empty((_NV, 3))
    ms = np.empty((_NM, 3, 3))
    for e in range(elements.shape[0]):
        _one_element(e, x, Q, elements, shift, E0, L0, EA, GJ, EIy, EIz, kGA, eps0,
                     fe, Ke, Rr, lcur, theta, forces, energy, ws, vs, ms, True)
