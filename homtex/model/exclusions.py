"""Same-yarn filter by arc length: pairs of one yarn too close along it to be real contacts.

With elements shorter than the yarn diameter, neighbouring segments of one yarn lie inside
the contact distance of each other: a straight yarn's elements i and j are |ell| apart, where
ell is the arc length of the elements strictly between them. A yarn can only touch itself
after turning round, over an arc of at least pi r (a half turn of centre-line radius r >= the
section's radius), so pairs of one yarn with ell < 2 max(r_a, r_b) + margin are never
contacts. Elements that share a node (of any yarn) are excluded as well.

:func:`arc_exclusions` returns the CSR lists that :class:`homtex.contact.broad.BroadPhase`
takes as ``exclusions`` (the same format as :func:`homtex.contact.broad.exclusion_lists`).
Arc lengths are those of the reference geometry (element lengths hardly change: the beams are
small-strain). ``margin`` must exceed the enforcement's activation gap ghat (so that a straight
yarn's first kept pair, ell >= 2 r + margin, is inactive) plus what bending takes from the
chord; its default r (ell < 3 r, below pi r) leaves that room for the usual ghat << r.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..errors import InputError


@njit(cache=True)
def _arc_kernel(elements, images, yarn, length, radius, node_ptr, inc, margin, k, cap, max_out):
    m = elements.shape[0]
    ptr = np.zeros(m + 1, dtype=np.int64)
    out_e = np.empty(max_out, dtype=np.int64)
    out_i = np.empty((max_out, k), dtype=np.int64)
    st_e = np.empty(cap, dtype=np.int64)
    st_i = np.empty((cap, k), dtype=np.int64)
    st_l = np.empty(cap)
    gi = np.empty(k, dtype=np.int64)
    tau = np.empty(k, dtype=np.int64)
    rmax = radius.max()
    pos = 0
    overflow = False
    for e in range(m):
        reach = 2.0 * rmax + margin
        n_st = 1
        st_e[0] = e
        st_i[0, :] = 0
        st_l[0] = 0.0
        head = 0
        while head < n_st:
            f = st_e[head]
            lf = st_l[head]
            cur = head
            head += 1
            if f != e and (yarn[f] != yarn[e] or lf + length[f] >= reach):
                continue
            lg = 0.0 if f == e else lf + length[f]
            for end in range(2):
                node = elements[f, end]
                for p in range(node_ptr[node], node_ptr[node + 1]):
                    g = inc[p]
                    if g == f:
                        continue
                    if f != e and yarn[g] != yarn[e]:
                        continue
                    for q in range(k):
                        gi[q] = st_i[cur, q] + (images[f, q] if end == 1 else 0)
                    for gend in range(2):
                        if elements[g, gend] != node:
                            continue
                        for q in range(k):
                            tau[q] = gi[q] - images[g, q] if gend == 1 else gi[q]
                        seen = False
                        for r in range(n_st):
                            if st_e[r] == g:
                                same = True
                                for q in range(k):
                                    if st_i[r, q] != tau[q]:
                                        same = False
                                if same:
                                    seen = True
                                    if lg < st_l[r]:
                                        st_l[r] = lg
                                    break
                        if seen:
                            continue
                        if n_st >= cap:
                            overflow = True
                            continue
                        st_e[n_st] = g
                        st_i[n_st, :] = tau
                        st_l[n_st] = lg
                        n_st += 1
        for r in range(1, n_st):
            g = st_e[r]
            # a relative tolerance keeps the lists symmetric when ell sums differ by rounding
            lim = (2.0 * max(radius[e], radius[g]) + margin) * (1.0 - 1e-9)
            if st_l[r] == 0.0 or (yarn[g] == yarn[e] and st_l[r] < lim):
                if pos < max_out:
                    out_e[pos] = g
                    out_i[pos, :] = st_i[r]
                pos += 1
        ptr[e + 1] = pos
    return ptr, out_e, out_i, overflow


def arc_exclusions(frame, margin: float | None = None) -> tuple:
    """Element pairs never treated as contacts: same yarn and closer than 2 r + margin along it.

    Parameters
    ----------
    frame : :class:`homtex.Frame` (elements, images, yarn ids, reference lengths, contact radii).
    margin : mm (>= 0); default the largest contact radius (excludes ell < 3 r).

    Returns ``(ptr (m+1,), elem (p,), image (p, k))``: element e excludes ``elem[ptr[e]:ptr[e+1]]``
    placed at the given images (relative to e), for :class:`~homtex.contact.broad.BroadPhase`.
    """
    r = np.ascontiguousarray(frame.contact_radius, dtype=float)
    if margin is None:
        margin = float(r.max())
    if not (np.isfinite(margin) and margin >= 0):
        raise InputError(f"margin (mm) must be finite and >= 0, got {margin!r}")
    el = frame.elements
    m = len(el)
    n = frame.n_nodes
    ends = np.concatenate([el[:, 0], el[:, 1]])
    order = np.argsort(ends, kind="stable")
    inc = np.ascontiguousarray(order % m)
    node_ptr = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(np.bincount(ends, minlength=n), out=node_ptr[1:])
    k = frame.dim_periodic
    length = np.ascontiguousarray(frame.length, dtype=float)
    reach = 2.0 * r.max() + margin
    deg = int(np.diff(node_ptr).max())
    cap = int(2 * deg * (reach / max(length.min(), 1e-12) + 2)) + 16
    args = (el, frame.images, frame.yarn, length, r, node_ptr, inc, float(margin), k, cap)
    ptr, e, i, overflow = _arc_kernel(*args, cap * m)
    if overflow:
        raise InputError("arc_exclusions: too many elements within reach of one element "
                         f"(more than {cap}); is the margin ({margin} mm) far larger than the elements?")
    if ptr[-1] > len(e):  # pragma: no cover - a guard; cap * m bounds the output
        ptr, e, i, _ = _arc_kernel(*args, int(ptr[-1]))
    return ptr, e[:ptr[-1]].copy(), np.ascontiguousarray(i[:ptr[-1]])
