"""Measuring a seam cell: the cushion profile on the outer yarn surfaces, and the check that
the stitch still holds the fabric between its threads."""

from __future__ import annotations

import numpy as np

__all__ = ["measure_profile", "thread_escape"]


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

    Returns (x (2 n_x w,) bin centres relative to the seam line in [-d/2, d/2), mm; h (same), mm).
    """
    x = frame.nodes if u is None else frame.nodes + np.asarray(u)[:frame.n_nodes, :3]
    top, bot, r = _surface_nodes(frame, info)
    w = float(info["wale_spacing"])
    d = float(info["seam_distance"])
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
