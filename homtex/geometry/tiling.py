"""Frames from frames: tiling a periodic frame into a supercell, and periodising a frame drawn
in a box. Both copy the per-element fields through :meth:`homtex.Frame.element_fields`."""

from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from ..errors import InputError
from ..model.arrays import MAX_COORD, as_index, as_real
from ..model.frame import Frame
from ..validate import check_number

__all__ = ["periodize", "tile_frame"]


def _physical_yarns(n, ea, eb, yarn, bond):
    """Yarn id per element of a tiled frame: one id per connected chain of same-yarn elements
    (a yarn that leaves one copy continues in the next); bonds take the id of their second node."""
    keep = ~bond
    g = coo_matrix((np.ones(int(keep.sum())), (ea[keep], eb[keep])), shape=(n, n))
    _, lab = connected_components(g, directed=False)
    # renumber in order of first appearance along the elements (stable, deterministic)
    first = lab[np.where(keep, ea, eb)]
    _, inv = np.unique(first, return_inverse=True)
    return inv.astype(np.int64)


def tile_frame(frame: Frame, n_x: int, n_y: int, bond=None):
    """Tile a 2-periodic frame n_x x n_y times.

    Returns (frame, node_copy (n',) copy index i*n_y + j, elem_copy (m',), elem_src (m',) source element).
    Yarn ids are renumbered per physical yarn (connected chain of elements that are not bonds;
    ``bond`` (m,) bool marks the base frame's bond elements, which take the id of their second node).
    """
    n, m = frame.n_nodes, frame.n_elements
    bond = np.zeros(m, dtype=bool) if bond is None else np.asarray(bond, dtype=bool)
    p = frame.periods
    ncp = n_x * n_y
    ii, jj = np.divmod(np.arange(ncp), n_y)
    nodes = (frame.nodes[None, :, :] + (ii[:, None, None] * p[0] + jj[:, None, None] * p[1])).reshape(-1, 3)
    img = frame.images
    a = frame.elements[:, 0]
    b = frame.elements[:, 1]
    ti = ii[:, None] + img[None, :, 0]
    tj = jj[:, None] + img[None, :, 1]
    ci, new_ix = np.mod(ti, n_x), np.floor_divide(ti, n_x)
    cj, new_iy = np.mod(tj, n_y), np.floor_divide(tj, n_y)
    ea = (np.arange(ncp)[:, None] * n + a[None, :]).ravel()
    eb = ((ci * n_y + cj) * n + b[None, :]).ravel()
    images = np.column_stack([new_ix.ravel(), new_iy.ravel()])
    yarn = _physical_yarns(n * ncp, ea, eb, np.tile(frame.yarn, ncp), np.tile(bond, ncp))
    fields = frame.element_fields(select=np.tile(np.arange(m), ncp))
    fields["yarn"] = yarn
    out = Frame(nodes, np.column_stack([ea, eb]), periods=np.array([n_x * p[0], n_y * p[1]]), images=images,
                **fields)
    return out, np.repeat(np.arange(ncp), n), np.repeat(np.arange(ncp), m), np.tile(np.arange(m), ncp)


def periodize(frame: Frame, box, *, axes=None, tol: float = 1e-6) -> Frame:
    """A periodic Frame from a frame drawn in an axis-aligned box.

    Nodes on an upper face of the box (coordinate = hi within ``tol`` along a periodic
    axis) are merged with their partners on the lower face (coordinate = lo, the other
    coordinates equal within ``tol``, modulo the other periods for edges and corners);
    elements that reached an upper-face node get the matching image offset. Elements
    that become duplicates (struts drawn on both opposite faces) are kept once.

    Parameters
    ----------
    frame : Frame (non-periodic), mm.
    box : (2, 3) array [lo, hi] of the box corners, mm.
    axes : periodic axes (subset of 0, 1, 2); default every axis with hi > lo.
    tol : pairing tolerance, mm.

    Returns
    -------
    Frame with ``periods`` = diag(hi - lo) rows of the periodic axes; the nodes of the
    upper faces are removed and the rest renumbered in order.

    Raises
    ------
    InputError listing the boundary nodes without a partner on the opposite face.
    """
    if frame.dim_periodic:
        raise InputError("periodize: the frame is already periodic")
    if not isinstance(frame, Frame):
        raise InputError(f"frame must be a homtex.Frame, got {type(frame).__name__}")
    box = as_real(box, "box", limit=MAX_COORD)
    if box.shape != (2, 3):
        raise InputError(f"box must be a (2, 3) array [lo, hi], got shape {box.shape}")
    tol = check_number(tol, "tol (pairing tolerance, mm)", gt=0.0, le=MAX_COORD)
    lo, hi = box
    if axes is None:
        axes = [a for a in range(3) if hi[a] - lo[a] > tol]
    axes = sorted(as_index(np.atleast_1d(axes) if not isinstance(axes, str) else axes, "axes", ndim=1,
                           lo=0, hi=2).tolist())
    if not axes or len(set(axes)) != len(axes):
        raise InputError(f"periodize: periodic axes must be a non-empty subset of 0, 1, 2, got {axes}")
    for a in axes:
        if not hi[a] - lo[a] > tol:
            raise InputError(f"periodize: box extent along axis {a} is {hi[a] - lo[a]}, must be > tol")
    x = frame.nodes
    outside = np.any((x < lo - tol) | (x > hi + tol), axis=1)
    if outside.any():
        bad = np.flatnonzero(outside)
        raise InputError(f"periodize: {len(bad)} nodes lie outside the box, e.g. node {bad[0]} at "
                         f"{x[bad[0]].tolist()}; nodes {bad[:20].tolist()}")
    Lp = hi - lo
    k = len(axes)
    on_hi = np.column_stack([np.abs(x[:, a] - hi[a]) <= tol for a in axes])
    on_lo = np.column_stack([np.abs(x[:, a] - lo[a]) <= tol for a in axes])
    img = on_hi.astype(np.int64)  # (n, k)
    canon = x.copy()
    for c, a in enumerate(axes):
        canon[:, a] -= img[:, c] * Lp[a]
    master = ~on_hi.any(axis=1)
    midx = np.flatnonzero(master)
    tree = cKDTree(canon[midx])
    dist, nearest = tree.query(canon, distance_upper_bound=tol * np.sqrt(3) * 1.0001)
    found = np.isfinite(dist)
    target = np.where(found, midx[np.minimum(nearest, len(midx) - 1)], -1)
    target[master] = midx
    unpaired_hi = np.flatnonzero(~master & ~found)
    # a lower-face node needs a partner on the upper face
    slaves = np.flatnonzero(~master & found)
    need = np.zeros((len(x), k), dtype=bool)
    for c in range(k):
        sel = slaves[on_hi[slaves, c]]
        need[target[sel], c] = True
    unpaired_lo = np.flatnonzero((on_lo & ~need & master[:, None]).any(axis=1))
    if len(unpaired_hi) or len(unpaired_lo):
        lines = []
        for i in unpaired_hi[:20]:
            lines.append(f"  node {i} at {x[i].tolist()} (upper face) has no partner on the lower face")
        for i in unpaired_lo[:20]:
            faces = [axes[c] for c in range(k) if on_lo[i, c] and not need[i, c]]
            lines.append(f"  node {i} at {x[i].tolist()} (lower face, axis {faces}) has no "
                         f"partner on the upper face")
        total = len(unpaired_hi) + len(unpaired_lo)
        raise InputError(f"periodize: {total} boundary node(s) without a partner within tol={tol} mm:\n"
                         + "\n".join(lines))
    new_id = -np.ones(len(x), dtype=np.int64)
    new_id[midx] = np.arange(len(midx))
    el = frame.elements
    a_, b_ = el[:, 0], el[:, 1]
    eimg = img[b_] - img[a_]
    elements = np.column_stack([new_id[target[a_]], new_id[target[b_]]])
    # duplicates (struts drawn on both opposite faces) are kept once
    swap = elements[:, 0] > elements[:, 1]
    lo_e = np.where(swap, elements[:, 1], elements[:, 0])
    hi_e = np.where(swap, elements[:, 0], elements[:, 1])
    im_c = np.where(swap[:, None], -eimg, eimg)
    same = lo_e == hi_e
    if same.any():
        first = np.zeros(len(el), dtype=np.int64)
        for c in range(k - 1, -1, -1):
            first = np.where(im_c[:, c] != 0, im_c[:, c], first)
        im_c = np.where((same & (first < 0))[:, None], -im_c, im_c)
    _, keep = np.unique(np.column_stack([lo_e, hi_e, im_c]), axis=0, return_index=True)
    keep = np.sort(keep)
    periods = np.zeros((k, 3))
    for c, a in enumerate(axes):
        periods[c, a] = Lp[a]
    return Frame(canon[midx], elements[keep], periods=periods, images=eimg[keep],
                 **frame.element_fields(select=keep))
