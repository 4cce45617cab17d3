"""Measuring a seam cell: the cushion profile on the outer yarn surfaces, and the check that
the stitch still holds the fabric between its threads."""

from __future__ import annotations

import numpy as np

__all__ = ["leg_shortening", "measure_profile", "pile_legs", "thread_escape"]


def _surface_nodes(frame, info):
    """Top- and bottom-layer node indices of the fabric and their outer radius (mm), (n,) arrays."""
    layer = np.asarray(info["layer"])
    n = frame.n_nodes
    r = np.zeros(n)
    out = {}
    for lay in ("top", "bottom"):
        el = frame.elements[layer == lay]
        rc = frame.contact_radius[layer == lay]
        np.maximum.at(r, el[:, 0], rc)
        np.maximum.at(r, el[:, 1], rc)
        out[lay] = np.unique(el.ravel())
    return out["top"], out["bottom"], r


def measure_profile(frame, info, u=None):
    """Cushion profile h(x) of a seam cell (mm): per x bin (one wale wide, centred on the wale
    centres, bin 0 on the seam line) the distance between the outermost top-layer yarn surface
    (max z + r) and the outermost bottom-layer yarn surface (min z - r); stitch yarn excluded.

    Returns (x (n_x,) bin centres relative to the seam line in [-d/2, d/2), mm; h (same), mm); a strip
    of k seams (``info["seams"]``): over its period k d, relative to its first seam.
    """
    x = frame.nodes if u is None else frame.nodes + np.asarray(u)[:frame.n_nodes, :3]
    top, bot, r = _surface_nodes(frame, info)
    w = float(info["wale_spacing"])
    d = float(info["seam_distance"]) * int(info.get("seams", 1))    # the x period
    nb = int(round(d / w))
    X = x[:, 0] - float(info["seam_x"])
    k = np.mod(np.round(X / w).astype(np.int64), nb)          # bin of each node, 0 = seam line
    zt = np.full(nb, -np.inf)
    zb = np.full(nb, np.inf)
    np.maximum.at(zt, k[top], x[top, 2] + r[top])
    np.minimum.at(zb, k[bot], x[bot, 2] - r[bot])
    kk = np.arange(nb)
    centre = np.where(kk < (nb + 1) // 2, kk, kk - nb) * w    # [-d/2, d/2)
    order = np.argsort(centre)
    h = zt - zb
    return centre[order], h[order]


def thread_escape(frame, info, u) -> str:
    """'' if the stitch still holds the fabric between its threads at the seam line, else which
    thread slipped through its layer (through an opening between the yarns, or a contact missed
    in a large step): the stitch is then unloaded and the fabric floats, a state the contact
    solve accepts as an equilibrium.

    Criterion: g = mean height of the layer's nodes within half a wale of the seam line minus the
    thread's mean height (bottom layer over the bobbin thread; top layer: needle thread minus
    layer). As sewn, g = g0 > 0 (about a yarn radius). A thread pressed into its layer lowers g a
    little (the default cell at eps0 = 0.3 ends at g = -0.13 mm for the needle thread, the thread
    nestled between loop legs); a thread that went through makes g fall by millimetres. Escaped:
    g < -g0."""
    Lx = float(frame.periods[0, 0])
    layer = np.asarray(info["layer"])
    out = []
    for side, thread, sign in (("bottom", "bobbin", 1.0), ("top", "needle", -1.0)):
        nodes = np.unique(frame.elements[layer == side])
        g = []
        for xyz in (frame.nodes, frame.nodes + np.asarray(u)[:frame.n_nodes, :3]):
            dx = (xyz[nodes, 0] - float(info["seam_x"]) + 0.5 * Lx) % Lx - 0.5 * Lx
            near = nodes[np.abs(dx) < 0.5 * float(info["wale_spacing"])]
            if not len(near):
                break
            g.append(sign * (xyz[near, 2].mean() - xyz[info[f"{thread}_nodes"], 2].mean()))
        if len(g) == 2 and g[1] < -abs(g[0]):
            out.append(f"the {thread} thread slipped through the {side} layer: the layer's mean height at the "
                       f"seam line is {-g[1]:.3g} mm on the wrong side of it (as sewn {g[0]:.3g} mm on the right side)")
    return "; ".join(out)



def pile_legs(frame, info) -> list:
    """The pile legs of a seam cell: arrays of element indices, one per leg from one layer to the other.

    A leg is a connected run of pile elements (group "pile") that run through the thickness (their
    direction's z component above half their length in the reference geometry; the pile's loops
    inside the layers lie flat)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    pile = np.asarray(info["groups"]["pile"], dtype=bool)
    el = frame.elements
    v = frame.element_vectors
    idx = np.flatnonzero(pile & (np.abs(v[:, 2]) > 0.5 * np.linalg.norm(v, axis=1)))
    if not len(idx):
        return []
    n = frame.n_nodes
    g = coo_matrix((np.ones(len(idx)), (el[idx, 0], el[idx, 1])), shape=(n, n))
    _, label = connected_components(g, directed=False)
    lab = label[el[idx, 0]]
    return [idx[lab == k] for k in np.unique(lab)]


def leg_shortening(frame, info, u, legs=None):
    """Per pile leg (:func:`pile_legs`): the x of its centre relative to the seam line (mm, in
    [-d/2, d/2)) and the relative loss of its end-to-end length at displacement u (n, 6),
    1 - |end-to-end| / reference (periodic jumps taken care of: the end-to-end vector is the sum of
    the leg's element vectors oriented upwards). Returns ((k,), (k,))."""
    legs = pile_legs(frame, info) if legs is None else legs
    x1 = frame.nodes + np.asarray(u)[:frame.n_nodes, :3]
    v0 = frame.element_vectors
    el = frame.elements
    sh = frame.shift
    v1 = x1[el[:, 1]] + sh - x1[el[:, 0]]
    d = float(info["seam_distance"]) * int(info.get("seams", 1))     # the x period
    xc, loss = [], []
    for e in legs:
        sgn = np.sign(v0[e, 2])[:, None]
        r0 = float(np.linalg.norm((sgn * v0[e]).sum(axis=0)))
        r1 = float(np.linalg.norm((sgn * v1[e]).sum(axis=0)))
        loss.append(1.0 - r1 / r0 if r0 > 0 else 0.0)
        xm = float(x1[el[e, 0], 0].mean()) - float(info["seam_x"])
        xc.append((xm + 0.5 * d) % d - 0.5 * d)
    return np.array(xc), np.array(loss)
