"""Yarn centerlines as curves: periodic Catmull-Rom splines through control points, chains
wrapped into a periodic cell, segment distances and the overlaps of a generated frame."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ..model.frame import Frame

__all__ = ["catmull_rom_periodic", "overlap_summary", "reference_vectors", "segment_distances", "wrap_chain",
           "yarn_overlaps"]


def catmull_rom_periodic(points: np.ndarray, closing: np.ndarray, n_per_segment: np.ndarray,
                         alpha: float = 0.5) -> np.ndarray:
    """Sample a centripetal Catmull-Rom curve through control points, periodic up to a translation.

    Parameters
    ----------
    points : (k, 3) control points P_0..P_{k-1}; the curve continues with P_0 + closing.
    closing : (3,) translation after one period.
    n_per_segment : (k,) int, samples per segment P_i -> P_{i+1} (P_k = P_0 + closing).
    alpha : 0.5 centripetal (no cusps or self-intersections within a segment).

    Returns
    -------
    (sum(n_per_segment), 3) samples: for each segment its start point and n - 1 interior points.
    """
    P = np.asarray(points, float)
    k = len(P)
    D = np.asarray(closing, float)
    ext = np.concatenate([P[-1:] - D, P, P[:2] + D])       # P_{-1}, P_0..P_{k-1}, P_k, P_{k+1}
    p0, p1, p2, p3 = ext[:-3], ext[1:-2], ext[2:-1], ext[3:]
    eps = 1e-12

    def dt(a, b):
        return np.maximum(np.linalg.norm(b - a, axis=1) ** alpha, eps)

    t1 = dt(p0, p1)
    t2 = t1 + dt(p1, p2)
    t3 = t2 + dt(p2, p3)
    n = np.asarray(n_per_segment, dtype=np.int64)
    seg = np.repeat(np.arange(k), n)
    local = np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)
    frac = local / n[seg]
    T1, T2, T3 = t1[seg, None], t2[seg, None], t3[seg, None]
    t = T1 + frac[:, None] * (T2 - T1)
    q0, q1, q2, q3 = p0[seg], p1[seg], p2[seg], p3[seg]
    A1 = (T1 - t) / T1 * q0 + t / T1 * q1
    A2 = (T2 - t) / (T2 - T1) * q1 + (t - T1) / (T2 - T1) * q2
    A3 = (T3 - t) / (T3 - T2) * q2 + (t - T2) / (T3 - T2) * q3
    B1 = (T2 - t) / T2 * A1 + t / T2 * A2
    B2 = (T3 - t) / (T3 - T1) * A2 + (t - T1) / (T3 - T1) * A3
    return (T2 - t) / (T2 - T1) * B1 + (t - T1) / (T2 - T1) * B2


def wrap_chain(points: np.ndarray, periods: np.ndarray, closing_image: np.ndarray):
    """Wrap a closed chain of unwrapped points into the periodic cell.

    ``points`` (n, 3) are consecutive nodes of one yarn; the chain closes from the
    last point to ``points[0] + closing_image @ periods``. Returns wrapped nodes
    (n, 3), elements (n, 2) (local indices) and images (n, k) such that every
    element vector equals the unwrapped difference.
    """
    P = np.asarray(periods, float)
    G = P @ P.T
    frac = np.linalg.solve(G, P @ points.T).T           # lattice coordinates (orthogonal in-plane cells)
    cell = np.floor(frac + 1e-9).astype(np.int64)
    wrapped = points - cell @ P
    n = len(points)
    a = np.arange(n)
    b = np.roll(a, -1)
    images = cell[b] - cell[a]
    images[-1] += np.asarray(closing_image, dtype=np.int64)
    return wrapped, np.column_stack([a, b]), images


def segment_distances(p1, d1, p2, d2):
    """Closest distance between segments p1 + s d1 and p2 + t d2 (s, t in [0, 1]), row-wise.

    All arrays (q, 3). Returns (dist, s, t).
    """
    r = p1 - p2
    a = np.einsum("ij,ij->i", d1, d1)
    e = np.einsum("ij,ij->i", d2, d2)
    f = np.einsum("ij,ij->i", d2, r)
    c = np.einsum("ij,ij->i", d1, r)
    b = np.einsum("ij,ij->i", d1, d2)
    den = a * e - b * b
    par = den <= 1e-12 * a * e
    s = np.where(par, 0.0, np.clip((b * f - c * e) / np.where(par, 1.0, den), 0.0, 1.0))
    t = (b * s + f) / e
    s = np.where(t < 0.0, np.clip(-c / a, 0.0, 1.0), np.where(t > 1.0, np.clip((b - c) / a, 0.0, 1.0), s))
    t = np.clip(t, 0.0, 1.0)
    diff = p1 + s[:, None] * d1 - p2 - t[:, None] * d2
    return np.linalg.norm(diff, axis=1), s, t


def yarn_overlaps(frame: Frame, *, tol: float = 1e-9, arc_exclusion: float = 3.0) -> np.ndarray:
    """Pairs of yarn segments that interpenetrate (distance < sum of contact radii).

    Segments of different yarns, and segments of the same yarn further apart
    along it than ``arc_exclusion * (r1 + r2)``, are checked, periodic images
    included (shifts of -1, 0, +1 per lattice vector). Same-yarn exclusion
    assumes each yarn's elements form a chain in element order (as the generators
    build them).

    Returns
    -------
    structured array with fields element_a, element_b, yarn_a, yarn_b (int64),
    depth (mm, r1 + r2 - distance > tol) and image (k,) of b, sorted by depth
    (largest first, ties in element order); each pair once.

    The candidates come from points sampled along every element at most ``h`` apart
    (``h`` = the largest contact diameter, or a quarter of the mean element length if that is
    larger), searched within ``h + 2 max(r)``: the search radius no longer grows with the
    longest element, so a cell with a few long and many short elements stays linear in its
    size (searching element midpoints within the longest element's length made a spacer cell
    with ``pile_segments = 2000`` take 9 s and 2.6 GB).
    """
    x0 = frame.nodes[frame.elements[:, 0]]
    d = frame.element_vectors
    rc = frame.contact_radius
    L = frame.length
    m = len(L)
    k = frame.dim_periodic
    imgs = np.array(np.meshgrid(*[[-1, 0, 1]] * k, indexing="ij")).reshape(k, -1).T if k else np.zeros((1, 0))
    imgs = imgs.astype(np.int64)
    shifts = imgs @ frame.periods if k else np.zeros((1, 3))
    # samples: every point of an element lies within h/2 of one of its samples, so two elements
    # closer than r_a + r_b have samples closer than h + r_a + r_b; at most about 5 m samples
    h = max(2.0 * float(rc.max()), float(L.sum()) / (4.0 * m)) if m else 1.0
    per = np.maximum(1, np.ceil(L / h)).astype(np.int64)
    owner = np.repeat(np.arange(m, dtype=np.int64), per)
    first = np.cumsum(per) - per
    frac = (np.arange(len(owner)) - first[owner] + 0.5) / per[owner]
    pts = x0[owner] + frac[:, None] * d[owner]
    reach = h + 2.0 * float(rc.max())
    # same yarn: neighbours along the yarn are never overlaps (arc length of each midpoint from
    # the yarn's first element, the yarn's total length for closed / periodic chains)
    cum = np.cumsum(L) - L
    _, first_el, ids = np.unique(frame.yarn, return_index=True, return_inverse=True)
    tot = np.bincount(ids, weights=L)[ids]
    s_loc = cum + 0.5 * L - cum[first_el[ids]]
    # each unordered pair once: a < b, or a == b with a "positive" image (first nonzero entry > 0)
    positive = np.array([next((int(v) for v in row if v != 0), 0) > 0 for row in imgs], dtype=bool)

    def candidates(a, b, q):
        keep = (a < b) | ((a == b) & positive[q])
        a, b = a[keep], b[keep]
        same = frame.yarn[a] == frame.yarn[b]
        ds = np.abs(s_loc[a] - s_loc[b])
        ds = np.minimum(ds, tot[a] - ds)
        near = same & (ds < arc_exclusion * (rc[a] + rc[b]) + 0.5 * (L[a] + L[b]))
        key = np.unique(a[~near] * m + b[~near])
        return key // m, key % m

    tree = cKDTree(pts)
    ea, eb, ei = [], [], []
    for q, sh in enumerate(shifts):
        # sparse distance matrix between the original samples and the shifted ones -> element pairs
        other = cKDTree(pts + sh)
        sdm = tree.sparse_distance_matrix(other, reach, output_type="coo_matrix")
        a, b = candidates(owner[sdm.row], owner[sdm.col], q)
        ea.append(a)
        eb.append(b)
        ei.append(np.full(len(a), q))
    a = np.concatenate(ea)
    b = np.concatenate(eb)
    qi = np.concatenate(ei)
    sh = shifts[qi]
    dist, _, _ = segment_distances(x0[a], d[a], x0[b] + sh, d[b])
    depth = rc[a] + rc[b] - dist
    hit = depth > tol
    a, b, qi, depth = a[hit], b[hit], qi[hit], depth[hit]
    order = np.lexsort((qi, b, a, -depth))     # deepest first; ties in element order
    out = np.zeros(len(order), dtype=[("element_a", np.int64), ("element_b", np.int64),
                                      ("yarn_a", np.int64), ("yarn_b", np.int64),
                                      ("depth", float), ("image", np.int64, (k,))])
    out["element_a"] = a[order]
    out["element_b"] = b[order]
    out["yarn_a"] = frame.yarn[a[order]]
    out["yarn_b"] = frame.yarn[b[order]]
    out["depth"] = depth[order]
    if k:
        out["image"] = imgs[qi[order]]
    return out


def overlap_summary(overlaps: np.ndarray, groups: dict | None = None, yarn_group: dict | None = None) -> str:
    """One line describing the overlaps (count, deepest, yarns / systems involved)."""
    if len(overlaps) == 0:
        return "no overlaps"
    o = overlaps[0]
    who = f"yarns {o['yarn_a']} and {o['yarn_b']}"
    if yarn_group:
        who += f" ({yarn_group.get(int(o['yarn_a']), '?')} / {yarn_group.get(int(o['yarn_b']), '?')})"
    return (f"{len(overlaps)} overlapping segment pairs, deepest {o['depth']:.4g} mm between elements "
            f"{o['element_a']} and {o['element_b']} of {who}")


def reference_vectors(nodes, elements, shift):
    """Per-element reference vector: global z, or global x for elements within ~25 degrees of z."""
    d = nodes[elements[:, 1]] + shift - nodes[elements[:, 0]]
    e1 = d / np.linalg.norm(d, axis=1)[:, None]
    ref = np.zeros_like(d)
    ref[:, 2] = 1.0
    ref[np.abs(e1[:, 2]) > 0.9] = (1.0, 0.0, 0.0)
    return ref
