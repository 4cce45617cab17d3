"""Kernels of periodic frames: equivalent loads of macro-strain jumps and case-pair work.

An element of a periodic frame sees the relative macro motion ``H @ d_e`` of its second end
(d_e the element vector, mm). :func:`jump_load_kernel` turns those jumps into nodal loads;
:func:`pair_work_kernel` sums the work of one case's end forces on another case's end
displacements (the energy form of the effective stiffness).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from .beam import coefficients


# kernels
@njit(cache=True, parallel=True)
def jump_load_kernel(node_ptr, inc_elem, inc_end, R, L, EA, GJ, EIy, EIz, kGA, dvec, H, out):
    """Equivalent nodal loads of the jumps ``H[q] @ dvec[e]`` of every element's second end.

    out (nc, n, 6) is overwritten: out[q, a] = -(sum over the element ends at node a of
    the global end force that the jump alone produces), i.e. b = -B^T K_e a(H).
    Parallel over nodes (each node owns its row), no atomics.
    """
    nc = H.shape[0]
    n = node_ptr.size - 1
    for a in prange(n):
        for q in range(nc):
            for c in range(6):
                out[q, a, c] = 0.0
        for p in range(node_ptr[a], node_ptr[a + 1]):
            e = inc_elem[p]
            s = inc_end[p]
            ax, tor, a_y, b_y, c_y, d_y, a_z, b_z, c_z, d_z = coefficients(
                L[e], EA[e], GJ[e], EIy[e], EIz[e], kGA[e])
            Re = R[e]
            for q in range(nc):
                # global jump, then local
                jg0 = H[q, 0, 0] * dvec[e, 0] + H[q, 0, 1] * dvec[e, 1] + H[q, 0, 2] * dvec[e, 2]
                jg1 = H[q, 1, 0] * dvec[e, 0] + H[q, 1, 1] * dvec[e, 1] + H[q, 1, 2] * dvec[e, 2]
                jg2 = H[q, 2, 0] * dvec[e, 0] + H[q, 2, 1] * dvec[e, 1] + H[q, 2, 2] * dvec[e, 2]
                j0 = Re[0, 0] * jg0 + Re[0, 1] * jg1 + Re[0, 2] * jg2
                j1 = Re[1, 0] * jg0 + Re[1, 1] * jg1 + Re[1, 2] * jg2
                j2 = Re[2, 0] * jg0 + Re[2, 1] * jg1 + Re[2, 2] * jg2
                # local end forces on the element of d = (0, 0, 0, 0, 0, 0, j0, j1, j2, 0, 0, 0)
                N = ax * j0
                dv = -j1
                dw = -j2
                if s == 0:
                    ft0 = -N
                    ft1 = a_y * dv
                    ft2 = a_z * dw
                    fm1 = -b_z * dw
                    fm2 = b_y * dv
                else:
                    ft0 = N
                    ft1 = -a_y * dv
                    ft2 = -a_z * dw
                    fm1 = -b_z * dw
                    fm2 = b_y * dv
                # global, with the minus sign of the load
                for c in range(3):
                    out[q, a, c] -= Re[0, c] * ft0 + Re[1, c] * ft1 + Re[2, c] * ft2
                    out[q, a, 3 + c] -= Re[1, c] * fm1 + Re[2, c] * fm2


@njit(cache=True, parallel=True)
def pair_work_kernel(elements, R, dvec, H, U, forces, nchunk):
    """out[q] = sum_e forces[e] . d_e(q) with d_e(q) the local end displacements of case q.

    U (nc, n, 6) fluctuations; H (nc, 3, 3) macro gradients; forces (m, 12) local end
    forces of one case. Returns (nc,) work, N mm.
    """
    m = elements.shape[0]
    nc = U.shape[0]
    part = np.zeros((nchunk, nc))
    size = (m + nchunk - 1) // nchunk
    for c in prange(nchunk):
        stop = min(m, (c + 1) * size)
        for e in range(c * size, stop):
            i = elements[e, 0]
            j = elements[e, 1]
            Re = R[e]
            f = forces[e]
            for q in range(nc):
                s = 0.0
                for r in range(3):
                    jr = H[q, r, 0] * dvec[e, 0] + H[q, r, 1] * dvec[e, 1] + H[q, r, 2] * dvec[e, 2]
                    # jump in global axis r contributes to every local component
                    for a in range(3):
                        Rar = Re[a, r]
                        s += Rar * (f[a] * U[q, i, r] + f[3 + a] * U[q, i, 3 + r]
                                    + f[6 + a] * (U[q, j, r] + jr) + f[9 + a] * U[q, j, 3 + r])
                part[c, q] += s
    return part.sum(axis=0)
