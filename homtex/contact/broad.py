"""Broad phase: candidate segment pairs on a uniform grid, periodic images included.

Segments are binned by midpoint into cubic cells of edge h = L_max + 2 r_max + margin,
so two segments closer than r_a + r_b + margin have midpoints at most h apart and sit
in neighbouring cells (27-cell stencil). For periodic frames, midpoints are wrapped
into the fundamental cell and copies ("ghosts") of segments near its faces are added,
so every periodic image within reach is found exactly once. Work and memory are O(n)
in the number of segments; the pair kernels run in parallel with numba.

Pairs are returned once: (a, b, image) with a < b, or a == b with a positive image
(a segment near its own periodic copy). ``image`` (k,) places segment b at
``b + image @ periods`` relative to a.
"""

from __future__ import annotations

import itertools

import numpy as np
from numba import njit, prange

from .narrow import closest_params, segment_pairs


# ----------------------------------------------------------------------------------------
# exclusions: elements that share a node, and same-yarn neighbours within a few hops
@njit(cache=True)
def _exclusion_kernel(elements, images, yarn, node_ptr, inc, hops, k, max_out):
    m = elements.shape[0]
    ptr = np.zeros(m + 1, dtype=np.int64)
    out_e = np.empty(max_out, dtype=np.int64)
    out_i = np.empty((max_out, k), dtype=np.int64)
    # per-element BFS over (element, image) states; chains give at most ~2*hops states
    cap = 64
    st_e = np.empty(cap, dtype=np.int64)
    st_i = np.empty((cap, k), dtype=np.int64)
    st_d = np.empty(cap, dtype=np.int64)
    pos = 0
    for e in range(m):
        n_st = 1
        st_e[0] = e
        for q in range(k):
            st_i[0, q] = 0
        st_d[0] = 0
        head = 0
        while head < n_st:
            f = st_e[head]
            dep = st_d[head]
            head += 1
            if dep >= hops:
                continue
            for end in range(2):
                node = elements[f, end]
                for p in range(node_ptr[node], node_ptr[node + 1]):
                    g = inc[p]
                    if g == f:
                        continue
                    # only same-yarn elements are followed beyond the first hop
                    if dep >= 1 and yarn[g] != yarn[e]:
                        continue
                    # image of g so that it shares this node with f (placed at st_i[head-1])
                    gi = np.empty(k, dtype=np.int64)
                    for q in range(k):
                        sig = st_i[head - 1, q] + (images[f, q] if end == 1 else 0)
                        gi[q] = sig
                    # node is g's end 0 (image sig) or end 1 (image sig - images[g])
                    for gend in range(2):
                        if elements[g, gend] != node:
                            continue
                        if gend == 1:
                            tau = gi - images[g]
                        else:
                            tau = gi.copy()
                        seen = False
                        for r in range(n_st):
                            if st_e[r] == g:
                                same = True
                                for q in range(k):
                                    if st_i[r, q] != tau[q]:
                                        same = False
                                if same:
                                    seen = True
                                    break
                        if seen or n_st >= cap:
                            continue
                        st_e[n_st] = g
                        for q in range(k):
                            st_i[n_st, q] = tau[q]
                        st_d[n_st] = dep + 1
                        n_st += 1
        for r in range(1, n_st):
            if pos < max_out:
                out_e[pos] = st_e[r]
                for q in range(k):
                    out_i[pos, q] = st_i[r, q]
            pos += 1
        ptr[e + 1] = pos
    return ptr, out_e, out_i


def exclusion_lists(frame, hops: int):
    """Pairs never treated as contacts, as CSR over elements.

    Elements that share a node (any yarn) and elements of the same yarn within ``hops``
    steps along the yarn (graph distance over shared nodes). Returns
    ``(ptr (m+1,), elem (p,), image (p, k))``: element e excludes ``elem[ptr[e]:ptr[e+1]]``
    placed at the given images.
    """
    el = frame.elements
    m = len(el)
    n = frame.n_nodes
    ends = np.concatenate([el[:, 0], el[:, 1]])
    order = np.argsort(ends, kind="stable")
    inc = np.ascontiguousarray(order % m)
    node_ptr = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(np.bincount(ends, minlength=n), out=node_ptr[1:])
    k = frame.dim_periodic
    deg = np.diff(node_ptr)
    per = int(2 * max(1, hops) * max(2, int(deg.max())) + 8)
    ptr, e, i = _exclusion_kernel(el, frame.images, frame.yarn, node_ptr, inc, max(1, int(hops)), k,
                                  per * m)
    if ptr[-1] > len(e):  # pragma: no cover - very branched frames
        ptr, e, i = _exclusion_kernel(el, frame.images, frame.yarn, node_ptr, inc, max(1, int(hops)), k,
                                      int(ptr[-1]))
    return ptr, e[:ptr[-1]].copy(), np.ascontiguousarray(i[:ptr[-1]])


# ----------------------------------------------------------------------------------------
@njit(cache=True)
def _bin_items(cell, ncell):
    counts = np.zeros(ncell + 1, dtype=np.int64)
    for j in range(cell.size):
        counts[cell[j] + 1] += 1
    for c in range(ncell):
        counts[c + 1] += counts[c]
    fill = counts[:-1].copy()
    order = np.empty(cell.size, dtype=np.int64)
    for j in range(cell.size):
        c = cell[j]
        order[fill[c]] = j
        fill[c] += 1
    return counts, order


@njit(cache=True, inline="always")
def _pair_test(a, b, j, wa, w, item_tau, k, p0w, d, r, lens, pos, item_pos, margin, excl_ptr, excl_e,
               excl_i, relimg, periods):
    """Whether item j (a copy of segment b) is a candidate for segment a; fills relimg."""
    nz = False
    first = 0
    for q in range(k):
        relimg[q] = w[b, q] + item_tau[j, q] - wa[q]
        if relimg[q] != 0 and not nz:
            nz = True
            first = relimg[q]
    if b == a and not (nz and first > 0):
        return False, 0.0, 0.0, 0.0
    reach = r[a] + r[b] + margin
    lim = 0.5 * (lens[a] + lens[b]) + reach
    dx = item_pos[j, 0] - pos[0]
    dy = item_pos[j, 1] - pos[1]
    dz = item_pos[j, 2] - pos[2]
    if dx * dx + dy * dy + dz * dz > lim * lim:
        return False, 0.0, 0.0, 0.0
    for p in range(excl_ptr[a], excl_ptr[a + 1]):
        if excl_e[p] == b:
            same = True
            for q in range(k):
                if excl_i[p, q] != relimg[q]:
                    same = False
            if same:
                return False, 0.0, 0.0, 0.0
    # segment b's copy: first end = p0w[b] + tau @ periods
    bx = p0w[b, 0]
    by = p0w[b, 1]
    bz = p0w[b, 2]
    for q in range(k):
        bx += item_tau[j, q] * periods[q, 0]
        by += item_tau[j, q] * periods[q, 1]
        bz += item_tau[j, q] * periods[q, 2]
    s, t = closest_params(p0w[a, 0], p0w[a, 1], p0w[a, 2], d[a, 0], d[a, 1], d[a, 2],
                          bx, by, bz, d[b, 0], d[b, 1], d[b, 2])
    ex = p0w[a, 0] + s * d[a, 0] - bx - t * d[b, 0]
    ey = p0w[a, 1] + s * d[a, 1] - by - t * d[b, 1]
    ez = p0w[a, 2] + s * d[a, 2] - bz - t * d[b, 2]
    dist = np.sqrt(ex * ex + ey * ey + ez * ez)
    return dist < reach, s, t, dist


@njit(cache=True, parallel=True)
def _grid_pairs(n, p0w, d, r, lens, w, item_orig, item_tau, item_pos, origin, h, dims, counts,
                order, margin, excl_ptr, excl_e, excl_i, periods, aorder, out_ptr, fill,
                out_b, out_img, out_s, out_t, out_dist):
    """Pass 1 (fill=False): count pairs per segment into out_ptr[a+1]. Pass 2: write them.

    Segments are visited in cell order (``aorder``) so that neighbouring iterations scan the
    same cells and items (cache reuse)."""
    k = w.shape[1]
    nx, ny, nz = dims[0], dims[1], dims[2]
    for ia in prange(n):
        a = aorder[ia]
        if fill and out_ptr[a + 1] == out_ptr[a]:
            continue                      # pass 1 found nothing for this segment
        pos = item_pos[a]
        cx = int((pos[0] - origin[0]) / h)
        cy = int((pos[1] - origin[1]) / h)
        cz = int((pos[2] - origin[2]) / h)
        relimg = np.empty(k, dtype=np.int64)
        wa = w[a]
        cnt = 0
        base = out_ptr[a] if fill else 0
        for ix in range(max(cx - 1, 0), min(cx + 2, nx)):
            for iy in range(max(cy - 1, 0), min(cy + 2, ny)):
                for iz in range(max(cz - 1, 0), min(cz + 2, nz)):
                    c = ix + nx * (iy + ny * iz)
                    for idx in range(counts[c], counts[c + 1]):
                        j = order[idx]
                        b = item_orig[j]
                        if b < a:
                            continue
                        ok, s, t, dist = _pair_test(a, b, j, wa, w, item_tau, k, p0w, d, r, lens, pos,
                                                    item_pos, margin, excl_ptr, excl_e, excl_i, relimg,
                                                    periods)
                        if ok:
                            if fill:
                                o = base + cnt
                                out_b[o] = b
                                for q in range(k):
                                    out_img[o, q] = relimg[q]
                                out_s[o] = s
                                out_t[o] = t
                                out_dist[o] = dist
                            cnt += 1
        if not fill:
            out_ptr[a + 1] = cnt


class BroadPhase:
    """Uniform-grid candidate search for one frame (exclusions computed once).

    Parameters
    ----------
    elements : (m, 2) node indices; images : (m, k); periods : (k, 3) lattice vectors (mm).
    radius : (m,) contact radius, mm.
    exclusions : (ptr, elem, image) from :func:`exclusion_lists`, or None.
    """

    def __init__(self, elements, radius, periods=None, images=None, exclusions=None):
        self.elements = np.ascontiguousarray(elements, dtype=np.int64)
        m = len(self.elements)
        self.radius = np.ascontiguousarray(radius, dtype=float)
        self.periods = np.zeros((0, 3)) if periods is None else np.ascontiguousarray(periods, dtype=float)
        k = len(self.periods)
        self.images = (np.zeros((m, k), dtype=np.int64) if images is None
                       else np.ascontiguousarray(images, dtype=np.int64).reshape(m, k))
        if exclusions is None:
            exclusions = (np.zeros(m + 1, dtype=np.int64), np.zeros(0, dtype=np.int64),
                          np.zeros((0, k), dtype=np.int64))
        self.exclusions = exclusions

    def pairs(self, nodes, margin: float):
        """Candidate pairs at node positions ``nodes`` (n, 3): centre-line distance < r_a + r_b + margin.

        Returns a dict with ``a``, ``b`` (c,), ``image`` (c, k), ``s``, ``t``, ``dist`` (c,).
        """
        x = np.asarray(nodes, dtype=float)
        el = self.elements
        shift = self.images @ self.periods if len(self.periods) else np.zeros((len(el), 3))
        p0 = x[el[:, 0]]
        d = x[el[:, 1]] + shift - p0
        return find_pairs(p0, d, self.radius, margin, self.periods, self.exclusions)


def find_pairs(p0, d, radius, margin, periods=None, exclusions=None):
    """Candidate segment pairs (see the module docstring).

    Parameters
    ----------
    p0 : (m, 3) first end of each segment, mm; d : (m, 3) segment vectors, mm.
    radius : (m,) contact radius, mm; margin : search margin added to r_a + r_b, mm.
    periods : (k, 3) lattice vectors, mm (k = 0..3).
    exclusions : CSR (ptr, elem, image) of excluded pairs.

    Returns dict a, b (c,), image (c, k), s, t, dist (c,).
    """
    p0 = np.ascontiguousarray(p0, dtype=float)
    d = np.ascontiguousarray(d, dtype=float)
    m = len(p0)
    r = np.ascontiguousarray(radius, dtype=float)
    periods = np.zeros((0, 3)) if periods is None else np.ascontiguousarray(periods, dtype=float).reshape(-1, 3)
    k = len(periods)
    if exclusions is None:
        exclusions = (np.zeros(m + 1, dtype=np.int64), np.zeros(0, dtype=np.int64),
                      np.zeros((0, k), dtype=np.int64))
    lens = np.sqrt(np.einsum("ij,ij->i", d, d))
    h = float(lens.max() + 2.0 * r.max() + margin)
    mid = p0 + 0.5 * d
    if k:
        dual = np.linalg.pinv(periods)  # (3, k): fractional coordinates f = x @ dual
        frac = mid @ dual
        w = -np.floor(frac).astype(np.int64)
        shiftw = w @ periods
        fw = frac + w
        # ghosts within a band of width h around the fundamental cell
        band = h * np.linalg.norm(dual, axis=0)
        reach = np.ceil(band).astype(int)
        orig_l, tau_l = [np.arange(m)], [np.zeros((m, k), dtype=np.int64)]
        # only items within ``band`` of a face can have ghosts (a small share for large sets)
        near = np.flatnonzero(np.any((fw < band) | (fw >= 1.0 - band), axis=1))
        fw_near = fw[near]
        for tau in itertools.product(*[range(-q, q + 1) for q in reach]):
            tau = np.asarray(tau, dtype=np.int64)
            if not tau.any():
                continue
            g = fw_near + tau
            sel = near[np.all((g >= -band) & (g < 1.0 + band), axis=1)]
            orig_l.append(sel)
            tau_l.append(np.broadcast_to(tau, (len(sel), k)))
        item_orig = np.concatenate(orig_l)
        item_tau = np.ascontiguousarray(np.concatenate(tau_l))
        p0w = np.ascontiguousarray(p0 + shiftw)
        midw = mid + shiftw
        item_pos = np.ascontiguousarray(midw[item_orig] + item_tau @ periods)
    else:
        w = np.zeros((m, 0), dtype=np.int64)
        item_orig = np.arange(m)
        item_tau = np.zeros((m, 0), dtype=np.int64)
        p0w = p0
        item_pos = np.ascontiguousarray(mid)
    origin = item_pos.min(axis=0) - 1e-9 * h
    ext = item_pos.max(axis=0) - origin
    # keep the number of cells O(items): enlarge h for sparse, spread-out sets
    while True:
        dims = (np.floor(ext / h) + 1).astype(np.int64)
        if dims.prod() <= 4 * len(item_pos) + 64:
            break
        h *= 1.26
    cell = np.floor((item_pos - origin) / h).astype(np.int64)
    cell = np.minimum(cell, dims - 1)
    cid = cell[:, 0] + dims[0] * (cell[:, 1] + dims[1] * cell[:, 2])
    counts, order = _bin_items(cid, int(dims.prod()))
    ex_ptr, ex_e, ex_i = exclusions
    ex_i = np.ascontiguousarray(ex_i, dtype=np.int64).reshape(len(ex_e), k)
    out_ptr = np.zeros(m + 1, dtype=np.int64)
    dummy_i = np.zeros((0, k), dtype=np.int64)
    dummy_f = np.zeros(0)
    dummy_b = np.zeros(0, dtype=np.int64)
    aorder = np.ascontiguousarray(order[order < m])   # the m primary items are segments 0..m-1
    args = (m, p0w, d, r, lens, np.ascontiguousarray(w), item_orig.astype(np.int64), item_tau, item_pos,
            origin, h, dims, counts, order, float(margin), ex_ptr, ex_e, ex_i, periods, aorder)
    _grid_pairs(*args, out_ptr, False, dummy_b, dummy_i, dummy_f, dummy_f, dummy_f)
    np.cumsum(out_ptr, out=out_ptr)
    c = int(out_ptr[-1])
    b = np.empty(c, dtype=np.int64)
    img = np.empty((c, k), dtype=np.int64)
    s = np.empty(c)
    t = np.empty(c)
    dist = np.empty(c)
    _grid_pairs(*args, out_ptr, True, b, img, s, t, dist)
    a = np.repeat(np.arange(m, dtype=np.int64), np.diff(out_ptr))
    return {"a": a, "b": b, "image": img, "s": s, "t": t, "dist": dist}


def find_pairs_kdtree(p0, d, radius, margin, box=None):
    """Reference broad phase with scipy.spatial.cKDTree (periodic box via ``boxsize``).

    ``box`` : (3,) box lengths of an orthogonal periodic box (use np.inf for a
    non-periodic direction), or None. Returns the same dict as :func:`find_pairs`
    (images as (c, 3) integer offsets along the box axes; exclusions not applied).
    """
    from scipy.spatial import cKDTree


    p0 = np.asarray(p0, float)
    d = np.asarray(d, float)
    r = np.asarray(radius, float)
    lens = np.linalg.norm(d, axis=1)
    h = float(lens.max() + 2 * r.max() + margin)
    mid = p0 + 0.5 * d
    if box is not None:
        box = np.asarray(box, float)
        per = np.isfinite(box)
        span = mid.max(axis=0) - mid.min(axis=0)
        bs = np.where(per, box, 4.0 * (span + h) + 1.0)
        lo = np.where(per, 0.0, mid.min(axis=0) - h)
        pts = mid - lo
        pts = np.where(per, np.mod(pts, bs), pts)
        tree = cKDTree(pts, boxsize=bs)
    else:
        pts = mid
        tree = cKDTree(pts)
    pairs = tree.query_pairs(h, output_type="ndarray")
    a, b = pairs[:, 0], pairs[:, 1]
    if box is not None:
        rel = mid[b] - mid[a]
        img = np.where(per, -np.round(rel / np.where(per, box, 1.0)), 0).astype(np.int64)
        shift = img * np.where(per, box, 0.0)
    else:
        img = np.zeros((len(a), 3), dtype=np.int64)
        shift = np.zeros((len(a), 3))
    s, t, dist, _ = segment_pairs(p0, d, a, b, shift)
    keep = dist < r[a] + r[b] + margin
    return {"a": a[keep], "b": b[keep], "image": img[keep], "s": s[keep], "t": t[keep],
            "dist": dist[keep]}
