"""Narrow phase: closest points of two segments, and node-plane gaps.

Segment 1 runs a + s u (s in [0, 1]), segment 2 runs b + t v (t in [0, 1]); lengths in mm.
The closest-point parameters are clamped to the segments. Parallel segments have
a whole interval of closest points: the middle of the overlap is taken, so the
normal and the force split stay symmetric (and do not jump between ends).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange


@njit(cache=True, inline="always")
def _clamp01(x):
    if x < 0.0:
        return 0.0
    if x > 1.0:
        return 1.0
    return x


@njit(cache=True, inline="always")
def closest_params(ax, ay, az, ux, uy, uz, bx, by, bz, vx, vy, vz):
    """Clamped closest-point parameters (s, t) of segments a + s u and b + t v."""
    rx = ax - bx
    ry = ay - by
    rz = az - bz
    A = ux * ux + uy * uy + uz * uz
    E = vx * vx + vy * vy + vz * vz
    B = ux * vx + uy * vy + uz * vz
    C = ux * rx + uy * ry + uz * rz
    F = vx * rx + vy * ry + vz * rz
    den = A * E - B * B
    if den > 1e-10 * A * E:
        s = _clamp01((B * F - C * E) / den)
        t = (B * s + F) / E
        if t < 0.0:
            t = 0.0
            s = _clamp01(-C / A)
        elif t > 1.0:
            t = 1.0
            s = _clamp01((B - C) / A)
    else:
        # parallel: project segment 2's ends on line 1, take the middle of the overlap
        s0 = -C / A
        s1 = (B - C) / A
        lo = max(0.0, min(s0, s1))
        hi = min(1.0, max(s0, s1))
        if lo <= hi:
            s = 0.5 * (lo + hi)
        elif max(s0, s1) < 0.0:
            s = 0.0
        else:
            s = 1.0
        t = _clamp01((B * s + F) / E)
        s = _clamp01((B * t - C) / A)
    return s, t


@njit(cache=True, parallel=True)
def segment_pairs_kernel(p0, d, ea, eb, shift_b, s_out, t_out, dist_out, n_out):
    """Closest points of segment pairs (ea[c], eb[c] shifted by shift_b[c]).

    p0 : (m, 3) first node of each segment; d : (m, 3) segment vectors.
    Writes s, t (c,), distance (c,) and the unit normal n (c, 3) pointing from
    segment eb to segment ea (the direction in which ea must move to separate).
    """
    c = ea.size
    for q in prange(c):
        a = ea[q]
        b = eb[q]
        bx = p0[b, 0] + shift_b[q, 0]
        by = p0[b, 1] + shift_b[q, 1]
        bz = p0[b, 2] + shift_b[q, 2]
        s, t = closest_params(p0[a, 0], p0[a, 1], p0[a, 2], d[a, 0], d[a, 1], d[a, 2],
                              bx, by, bz, d[b, 0], d[b, 1], d[b, 2])
        dx = p0[a, 0] + s * d[a, 0] - bx - t * d[b, 0]
        dy = p0[a, 1] + s * d[a, 1] - by - t * d[b, 1]
        dz = p0[a, 2] + s * d[a, 2] - bz - t * d[b, 2]
        dist = np.sqrt(dx * dx + dy * dy + dz * dz)
        la = np.sqrt(d[a, 0] ** 2 + d[a, 1] ** 2 + d[a, 2] ** 2)
        if dist > 1e-12 * la:
            nx, ny, nz = dx / dist, dy / dist, dz / dist
        else:
            # centre lines touch: normal of the plane of both segments, or any perpendicular
            nx = d[a, 1] * d[b, 2] - d[a, 2] * d[b, 1]
            ny = d[a, 2] * d[b, 0] - d[a, 0] * d[b, 2]
            nz = d[a, 0] * d[b, 1] - d[a, 1] * d[b, 0]
            nn = np.sqrt(nx * nx + ny * ny + nz * nz)
            if nn <= 1e-12 * la * la:
                # collinear: a perpendicular of segment a
                if abs(d[a, 0]) < 0.9 * la:
                    nx, ny, nz = 0.0, -d[a, 2], d[a, 1]
                else:
                    nx, ny, nz = -d[a, 2], 0.0, d[a, 0]
                nn = np.sqrt(nx * nx + ny * ny + nz * nz)
            if nx * 1e-3 + ny * 1e-6 + nz < 0.0:
                nn = -nn
            nx, ny, nz = nx / nn, ny / nn, nz / nn
        s_out[q] = s
        t_out[q] = t
        dist_out[q] = dist
        n_out[q, 0] = nx
        n_out[q, 1] = ny
        n_out[q, 2] = nz


def segment_pairs(p0, d, ea, eb, shift_b=None):
    """Closest points of segment pairs.

    Parameters
    ----------
    p0 : (m, 3) first end of each segment, mm; d : (m, 3) segment vectors, mm.
    ea, eb : (c,) segment indices; shift_b : (c, 3) translation of segment eb (periodic image).

    Returns
    -------
    s, t : (c,) clamped parameters on ea and eb; dist : (c,) centre-line distance (mm);
    normal : (c, 3) unit vector from eb's closest point to ea's.
    """
    ea = np.ascontiguousarray(ea, dtype=np.int64)
    eb = np.ascontiguousarray(eb, dtype=np.int64)
    c = ea.size
    if shift_b is None:
        shift_b = np.zeros((c, 3))
    s = np.empty(c)
    t = np.empty(c)
    dist = np.empty(c)
    n = np.empty((c, 3))
    if c:
        segment_pairs_kernel(np.ascontiguousarray(p0, dtype=float), np.ascontiguousarray(d, dtype=float),
                             ea, eb, np.ascontiguousarray(shift_b, dtype=float), s, t, dist, n)
    return s, t, dist, n


def closest_points_reference(a, u, b, v, samples: int = 2001):
    """Brute-force closest parameters by dense sampling + local refinement (tests only)."""
    a, u, b, v = (np.asarray(x, float) for x in (a, u, b, v))
    g = np.linspace(0.0, 1.0, samples)
    P = a + g[:, None] * u
    Q = b + g[:, None] * v
    D = np.linalg.norm(P[:, None, :] - Q[None, :, :], axis=2)
    i, j = np.unravel_index(np.argmin(D), D.shape)
    return g[i], g[j], float(D[i, j])


def node_plane_gaps(z, node_radius, plate_z, plate_normal):
    """Gap (mm) between nodes and a plane z = plate_z whose material side is ``plate_normal``.

    gap = normal * (z - plate_z) - node_radius, (n,) for node heights z (n,).
    """
    return plate_normal * (np.asarray(z) - plate_z) - node_radius
