"""Two-node 3D Timoshenko beam: exact stiffness of a straight prismatic member.

Local DOF order per node: u, v, w (along e1, e2, e3), theta_x, theta_y, theta_z.
Bending in the e1-e2 plane uses Iz and Phi_y = 12 E Iz / (k G A L^2); bending in
the e1-e3 plane uses Iy and Phi_z = 12 E Iy / (k G A L^2). With Phi -> 0 the
element is the Euler-Bernoulli beam; for any Phi it is exact for end loads,
so it does not lock.

The global 6x6 blocks are written as sums of outer products of the local axes
(rows of R) so kernels never build a 12x12 matrix.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange


@njit(cache=True, inline="always")
def coefficients(L, EA, GJ, EIy, EIz, kGA):
    """Scalar stiffness coefficients of one element.

    Returns (ax, tor, a_y, b_y, c_y, d_y, a_z, b_z, c_z, d_z) where for each
    bending plane a = 12EI/((1+Phi)L^3), b = 6EI/((1+Phi)L^2),
    c = (4+Phi)EI/((1+Phi)L), d = (2-Phi)EI/((1+Phi)L).
    """
    L2 = L * L
    phy = 12.0 * EIz / (kGA * L2)
    phz = 12.0 * EIy / (kGA * L2)
    sy = EIz / (1.0 + phy)
    sz = EIy / (1.0 + phz)
    return (EA / L, GJ / L,
            12.0 * sy / (L2 * L), 6.0 * sy / L2, (4.0 + phy) * sy / L, (2.0 - phy) * sy / L,
            12.0 * sz / (L2 * L), 6.0 * sz / L2, (4.0 + phz) * sz / L, (2.0 - phz) * sz / L)


@njit(cache=True, inline="always")
def add_block(out, R, t1, t2, t3, r1, r2, r3, tr23, tr32, rt23, rt32, scale):
    """out[6,6] += scale * global block from local diagonal/coupling coefficients.

    Translational part diag(t1, t2, t3), rotational diag(r1, r2, r3) in the local
    frame; coupling translation-rotation tr23 * e2 e3^T + tr32 * e3 e2^T (local
    entries (v, theta_z) and (w, theta_y)) and rotation-translation
    rt23 * e2 e3^T + rt32 * e3 e2^T (entries (theta_y, w) and (theta_z, v)).
    """
    for i in range(3):
        a1 = R[0, i]
        a2 = R[1, i]
        a3 = R[2, i]
        for j in range(3):
            b1 = R[0, j]
            b2 = R[1, j]
            b3 = R[2, j]
            p11 = a1 * b1
            p22 = a2 * b2
            p33 = a3 * b3
            p23 = a2 * b3
            p32 = a3 * b2
            out[i, j] += scale * (t1 * p11 + t2 * p22 + t3 * p33)
            out[3 + i, 3 + j] += scale * (r1 * p11 + r2 * p22 + r3 * p33)
            out[i, 3 + j] += scale * (tr23 * p23 + tr32 * p32)
            out[3 + i, j] += scale * (rt23 * p23 + rt32 * p32)


@njit(cache=True, inline="always")
def add_element_block(out, R, s, t, ax, tor, a_y, b_y, c_y, d_y, a_z, b_z, c_z, d_z, scale):
    """out += scale * block (s, t) (s, t in {0, 1}: element end) of the global element matrix."""
    if s == t:
        sg = 1.0 if s == 0 else -1.0
        # (v,thz) = +-b_y; (w,thy) = -+b_z; symmetric block
        add_block(out, R, ax, a_y, a_z, tor, c_z, c_y,
                  sg * b_y, -sg * b_z, -sg * b_z, sg * b_y, scale)
    elif s == 0:
        # (v1,thz2)=+b_y, (w1,thy2)=-b_z ; (thz1,v2)=-b_y, (thy1,w2)=+b_z
        add_block(out, R, -ax, -a_y, -a_z, -tor, d_z, d_y,
                  b_y, -b_z, b_z, -b_y, scale)
    else:
        # transpose of block (0, 1)
        add_block(out, R, -ax, -a_y, -a_z, -tor, d_z, d_y,
                  -b_y, b_z, -b_z, b_y, scale)


def local_stiffness(L, EA, GJ, EIy, EIz, kGA):
    """Dense 12x12 local stiffness (plain numpy; reference for tests)."""
    ax, tor, a_y, b_y, c_y, d_y, a_z, b_z, c_z, d_z = coefficients.py_func(L, EA, GJ, EIy, EIz, kGA)
    k = np.zeros((12, 12))
    for i, j in ((0, 0), (6, 6)):
        k[i, j] = ax
    k[0, 6] = k[6, 0] = -ax
    k[3, 3] = k[9, 9] = tor
    k[3, 9] = k[9, 3] = -tor
    # e1-e2 plane: (v1, thz1, v2, thz2) = (1, 5, 7, 11)
    idx = (1, 5, 7, 11)
    ky = np.array([[a_y, b_y, -a_y, b_y], [b_y, c_y, -b_y, d_y],
                   [-a_y, -b_y, a_y, -b_y], [b_y, d_y, -b_y, c_y]])
    # e1-e3 plane: (w1, thy1, w2, thy2) = (2, 4, 8, 10)
    idz = (2, 4, 8, 10)
    kz = np.array([[a_z, -b_z, -a_z, -b_z], [-b_z, c_z, b_z, d_z],
                   [-a_z, b_z, a_z, b_z], [-b_z, d_z, b_z, c_z]])
    k[np.ix_(idx, idx)] = ky
    k[np.ix_(idz, idz)] = kz
    return k


@njit(cache=True, inline="always")
def end_forces(d, ax, tor, a_y, b_y, c_y, d_y, a_z, b_z, c_z, d_z, pre):
    """Local end forces (12,) of the linear element for local end displacements d (12,);
    ``pre`` = EA eps0 is the pre-strain tension."""
    f = np.empty(12)
    N = ax * (d[6] - d[0]) + pre
    T = tor * (d[9] - d[3])
    dv = d[1] - d[7]
    fv1 = a_y * dv + b_y * (d[5] + d[11])
    fz1 = b_y * dv + c_y * d[5] + d_y * d[11]
    fz2 = b_y * dv + d_y * d[5] + c_y * d[11]
    dw = d[2] - d[8]
    fw1 = a_z * dw - b_z * (d[4] + d[10])
    fy1 = -b_z * dw + c_z * d[4] + d_z * d[10]
    fy2 = -b_z * dw + d_z * d[4] + c_z * d[10]
    f[0] = -N
    f[1] = fv1
    f[2] = fw1
    f[3] = -T
    f[4] = fy1
    f[5] = fz1
    f[6] = N
    f[7] = -fv1
    f[8] = -fw1
    f[9] = T
    f[10] = fy2
    f[11] = fz2
    return f


@njit(cache=True, inline="always")
def end_energy(f, Le, EA, GJ, EIy, EIz, kGA, out):
    """Strain-energy split (axial, torsion, bending_y, bending_z, shear) of local end forces f."""
    N = f[6]
    T = f[9]
    out[0] = 0.5 * N * N * Le / EA
    out[1] = 0.5 * T * T * Le / GJ
    # internal moment varies linearly from -f(end 1) to +f(end 2)
    m0 = -f[4]
    m1 = f[10]
    out[2] = Le / (6.0 * EIy) * (m0 * m0 + m0 * m1 + m1 * m1)
    m0 = -f[5]
    m1 = f[11]
    out[3] = Le / (6.0 * EIz) * (m0 * m0 + m0 * m1 + m1 * m1)
    out[4] = 0.5 * (f[1] * f[1] + f[2] * f[2]) * Le / kGA


@njit(cache=True, parallel=True)
def element_response(u, elements, jump, R, L, EA, GJ, EIy, EIz, kGA, eps0, forces, energy):
    """Local end forces and the strain-energy split of every element.

    Parameters
    ----------
    u : (n, 6) nodal displacements and rotations.
    jump : (m, 3) extra translation of each element's second node (periodic
        macro strain: H @ shift); zeros otherwise.
    forces : out (m, 12) local end forces acting on the element
        [N1, Vy1, Vz1, T1, My1, Mz1, N2, ...]; tension is forces[:, 6] > 0.
    energy : out (m, 5) axial, torsion, bending_y, bending_z, shear (N mm).
    """
    m = elements.shape[0]
    for e in prange(m):
        i = elements[e, 0]
        j = elements[e, 1]
        Re = R[e]
        d = np.empty(12)
        for a in range(3):
            s0 = 0.0
            s1 = 0.0
            s2 = 0.0
            s3 = 0.0
            for b in range(3):
                s0 += Re[a, b] * u[i, b]
                s1 += Re[a, b] * u[i, 3 + b]
                s2 += Re[a, b] * (u[j, b] + jump[e, b])
                s3 += Re[a, b] * u[j, 3 + b]
            d[a] = s0
            d[3 + a] = s1
            d[6 + a] = s2
            d[9 + a] = s3
        ax, tor, a_y, b_y, c_y, d_y, a_z, b_z, c_z, d_z = coefficients(
            L[e], EA[e], GJ[e], EIy[e], EIz[e], kGA[e])
        f = end_forces(d, ax, tor, a_y, b_y, c_y, d_y, a_z, b_z, c_z, d_z, EA[e] * eps0[e])
        forces[e] = f
        end_energy(f, L[e], EA[e], GJ[e], EIy[e], EIz[e], kGA[e], energy[e])


@njit(cache=True, parallel=True)
def prestrain_forces(elements, R, EA, eps0, out_elem):
    """Per-element equivalent nodal forces of an initial shortening strain eps0.

    out_elem : (m, 2, 3) translational forces on the two ends: +EA eps0 e1 on
    the first node and -EA eps0 e1 on the second (they pull the ends together).
    """
    m = elements.shape[0]
    for e in prange(m):
        p = EA[e] * eps0[e]
        for a in range(3):
            out_elem[e, 0, a] = p * R[e, 0, a]
            out_elem[e, 1, a] = -p * R[e, 0, a]
