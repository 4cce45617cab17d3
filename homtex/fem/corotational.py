"""Co-rotational 3D beam kernels: large rotations, small strains.

Each element carries a frame that follows it (the *co-rotated* frame Er, columns r1, r2, r3):
r1 along the current chord, r2/r3 fixed by the mean of the two rotated end axes e2. In Er the
element is the linear Timoshenko beam of :mod:`homtex.fem.beam`, loaded only by its stretch
l - l0 and its end *deformational* rotations theta_a = log(Er^T Q_a E0^T) (Q_a: rotation of
node a from the start, E0: initial element frame). Rigid motions of any size leave l - l0 and
theta unchanged, so they give exactly zero force; rotations within an element must stay
moderate (a few tenths of a radian), which mesh refinement ensures.

Internal forces are the exact gradient of the element energy
U = EA l0 / 2 ((l - l0) / l0 + eps0)^2 + 1/2 theta . K_theta theta
with respect to nodal translations and nodal spins (delta Q_a = spin(dw_a) Q_a), including the
tangent map of the rotation vector and the spin of the co-rotated frame; tests check them
against finite differences of U. The tangent used for Newton's method is approximate (the
linear stiffness in the current frame plus the axial-force geometric stiffness): the residual
is exact, so converged states are exact; only the convergence rate is affected.

Units: mm, N, MPa; arrays as in :mod:`homtex.fem.beam`.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from .beam import coefficients, end_energy, end_forces


@njit(cache=True, inline="always")
def _cross(a, b):
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


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
    """Rotation vector (3,) of a rotation matrix (angle < pi), via the quaternion (robust near 0)."""
    tr = R[0, 0] + R[1, 1] + R[2, 2]
    q0 = 0.5 * np.sqrt(max(1.0 + tr, 0.0))
    if q0 > 0.5:                    # angle < 120 degrees: the direct formula is well conditioned
        f = 0.25 / q0
        qv = np.array([(R[2, 1] - R[1, 2]) * f, (R[0, 2] - R[2, 0]) * f, (R[1, 0] - R[0, 1]) * f])
    else:                           # Shepperd: largest diagonal element
        k = 0
        if R[1, 1] > R[k, k]:
            k = 1
        if R[2, 2] > R[k, k]:
            k = 2
        i, j = (k + 1) % 3, (k + 2) % 3
        qk = 0.5 * np.sqrt(max(1.0 + R[k, k] - R[i, i] - R[j, j], 1e-300))
        f = 0.25 / qk
        qv = np.empty(3)
        qv[k] = qk
        qv[i] = (R[i, k] + R[k, i]) * f
        qv[j] = (R[j, k] + R[k, j]) * f
        q0 = (R[j, i] - R[i, j]) * f
        if q0 < 0.0:
            q0 = -q0
            qv = -qv
    s = np.sqrt(qv[0] * qv[0] + qv[1] * qv[1] + qv[2] * qv[2])
    if s < 1e-12:
        return 2.0 * qv / q0
    return (2.0 * np.arctan2(s, q0) / s) * qv


@njit(cache=True, inline="always")
def _tinv_t(th, m):
    """T^-T(theta) m: the moment conjugate to a spatial spin of Rd = exp(theta) from the moment m
    conjugate to theta (T^-1 = I - 1/2 S + eta S^2, S = spin(theta))."""
    t2 = th[0] * th[0] + th[1] * th[1] + th[2] * th[2]
    if t2 < 1e-8:
        eta = 1.0 / 12.0 + t2 / 720.0
    else:
        t = np.sqrt(t2)
        eta = (1.0 - 0.5 * t / np.tan(0.5 * t)) / t2
    a = _cross(th, m)
    b = _cross(th, a)
    return m + 0.5 * a + eta * b


@njit(cache=True, parallel=True)
def corotational_response(x, Q, elements, shift, E0, L0, EA, GJ, EIy, EIz, kGA, eps0,
                          fe, Rr, lcur, theta, forces, energy):
    """Co-rotational internal forces of every element.

    Parameters
    ----------
    x : (n, 3) current node positions, mm. Q : (n, 3, 3) nodal rotations from the start.
    shift : (m, 3) offset of each element's second node (periodic images), mm.
    E0 : (m, 3, 3) initial element frames (rows e1, e2, e3). L0 : (m,) initial lengths, mm.
    eps0 : (m,) pre-strain (tension positive).
    fe : out (m, 2, 6) forces and moments the element exerts on its two nodes' DOFs
        (internal force vector: the residual is f_ext - sum fe).
    Rr : out (m, 3, 3) co-rotated frames (rows r1, r2, r3). lcur : out (m,) current lengths.
    theta : out (m, 2, 3) end rotations relative to Rr (local axes), rad.
    forces : out (m, 12) local end forces in Rr (as :func:`homtex.fem.beam.element_response`).
    energy : out (m, 5) energy split, N mm.
    """
    m = elements.shape[0]
    for e in prange(m):
        i = elements[e, 0]
        j = elements[e, 1]
        dx = x[j] + shift[e] - x[i]
        l = np.sqrt(dx[0] * dx[0] + dx[1] * dx[1] + dx[2] * dx[2])
        r1 = dx / l
        Ti = Q[i] @ E0[e].T          # columns: rotated initial axes at end i
        Tj = Q[j] @ E0[e].T
        p = 0.5 * (Ti[:, 1] + Tj[:, 1])
        c = _cross(r1, p)
        s = np.sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2])
        r3 = c / s
        r2 = _cross(r3, r1)
        Er = np.empty((3, 3))
        Er[:, 0] = r1
        Er[:, 1] = r2
        Er[:, 2] = r3
        thi = logmap(Er.T @ Ti)
        thj = logmap(Er.T @ Tj)
        theta[e, 0] = thi
        theta[e, 1] = thj
        ax, tor, a_y, b_y, c_y, d_y, a_z, b_z, c_z, d_z = coefficients(
            L0[e], EA[e], GJ[e], EIy[e], EIz[e], kGA[e])
        d = np.zeros(12)
        d[6] = l - L0[e]
        d[3:6] = thi
        d[9:12] = thj
        f = end_forces(d, ax, tor, a_y, b_y, c_y, d_y, a_z, b_z, c_z, d_z, EA[e] * eps0[e])
        forces[e] = f
        end_energy(f, L0[e], EA[e], GJ[e], EIy[e], EIz[e], kGA[e], energy[e])
        N = f[6]
        Gi = Er @ _tinv_t(thi, f[3:6])
        Gj = Er @ _tinv_t(thj, f[9:12])
        S = Gi + Gj
        s1 = S[0] * r1[0] + S[1] * r1[1] + S[2] * r1[2]
        s2 = S[0] * r2[0] + S[1] * r2[1] + S[2] * r2[2]
        s3 = S[0] * r3[0] + S[1] * r3[1] + S[2] * r3[2]
        # spin of the co-rotated frame: about r2, r3 from the chord's turn, about r1 from p
        q = _cross(p, r2)
        q = q - (q[0] * r1[0] + q[1] * r1[1] + q[2] * r1[2]) * r1
        v = N * r1 + (s1 / (s * l)) * q + (s2 / l) * r3 - (s3 / l) * r2
        wi = _cross(Ti[:, 1], r3)
        wj = _cross(Tj[:, 1], r3)
        h = s1 / (2.0 * s)
        for a in range(3):
            fe[e, 0, a] = -v[a]
            fe[e, 1, a] = v[a]
            fe[e, 0, 3 + a] = Gi[a] - h * wi[a]
            fe[e, 1, 3 + a] = Gj[a] - h * wj[a]
            Rr[e, 0, a] = r1[a]
            Rr[e, 1, a] = r2[a]
            Rr[e, 2, a] = r3[a]
        lcur[e] = l


@njit(cache=True, parallel=True)
def gather_ends(node_ptr, inc_elem, inc_end, fe, out):
    """out (n, 6) = sum over the element ends at each node of fe (m, 2, 6) (no races: one node per thread)."""
    n = node_ptr.size - 1
    for a in prange(n):
        for k in range(6):
            out[a, k] = 0.0
        for p in range(node_ptr[a], node_ptr[a + 1]):
            e = inc_elem[p]
            s = inc_end[p]
            for k in range(6):
                out[a, k] += fe[e, s, k]


@njit(cache=True, parallel=True)
def add_geometric(node_ptr, inc_elem, inc_end, slot_self, slot_other, Rr, lcur, N, data):
    """data[nnzb, 6, 6] += axial-force geometric stiffness N / l (I - r1 r1^T) on translations
    (the turn of the chord under a fixed axial force)."""
    n = node_ptr.size - 1
    for a in prange(n):
        for p in range(node_ptr[a], node_ptr[a + 1]):
            e = inc_elem[p]
            g = N[e] / lcur[e]
            for r in range(3):
                for c in range(3):
                    v = g * ((1.0 if r == c else 0.0) - Rr[e, 0, r] * Rr[e, 0, c])
                    data[slot_self[p], r, c] += v
                    data[slot_other[p], r, c] -= v


@njit(cache=True, parallel=True)
def rotate_nodes(Q, dtheta):
    """Q[i] <- exp(dtheta[i]) Q[i] in place (spatial spin update), (n, 3, 3) and (n, 3)."""
    for i in prange(Q.shape[0]):
        Q[i] = expmap(dtheta[i]) @ Q[i]


@njit(cache=True, parallel=True)
def log_nodes(Q, out):
    """out (n, 3) = rotation vectors log(Q[i]) of (n, 3, 3) rotation matrices."""
    for i in prange(Q.shape[0]):
        out[i] = logmap(Q[i])
