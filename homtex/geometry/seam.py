"""Yarn-level seam cell: a 2-periodic spacer cell tiled across one seam distance, with a lock stitch 301.

Geometry (mm; x across the wales = across the seam, y along the wales = along the seam, z through
the thickness, fabric between z = 0 and z = T):

* The fabric cell (period p1 = (Lx, 0, 0), p2 = (0, Ly, 0)) is tiled ``n_x`` times along x and
  ``n_y`` times along y. The seam cell's periods are (n_x Lx, 0, 0) and (0, n_y Ly, 0): the x period
  is the seam distance d (rounded to a whole number of fabric repeats, see :func:`seam_tiling`), the
  y period is one stitch length s (or ``stitches`` of them), which must be a whole number of fabric
  repeats along y.
* The lock stitch 301 is one extra yarn (its own yarn id, group ``"stitch"``) at x = x_s (the
  centre of the first wale, so that the needle thread lies on the loop heads):

  - needle thread: a straight chain along y on the top surface, z = T + r_s, periodic in y;
  - bobbin thread: a straight chain along y under the bottom surface, z = -r_s, periodic in y;
  - at each stitch point (y = y_s + k s) the needle thread goes down through the fabric and the
    bobbin thread comes up; they interlock at the mid-plane z = T / 2. The interlock is modelled
    as a node shared by the two legs (the threads cannot slip through each other there); each leg
    is two thread strands (down and back up through the same needle hole), modelled as one
    centerline of twice the thread's cross-section area (circle of radius sqrt(2) r_s; contact
    radius r_s).

  Every stitch element carries the axial pre-strain eps0 (``Frame.prestrain``): it wants to be
  shorter by eps0. In this small-rotation beam model only the legs can shorten (the needle and
  bobbin chains are periodic along y with a fixed period), so the legs pull the needle thread
  down onto the top layer and the bobbin thread up against the bottom layer; the fabric is
  compressed at the seam line until its resistance balances the stitch tension.

Limitations: the thread does not slide through the needle hole (the tension is not equalised
between the surface chains and the legs), frictionless contact. The solvers (homtex.seams) use
geometrically linear beams by default and co-rotational ones on request.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import InputError
from ..model.frame import Frame, stack_fields
from .curves import segment_distances
from .tiling import tile_frame


def seam_tiling(cell, seam_distance: float, stitch_length: float, *, stitches: int = 1,
                exact: bool = False) -> dict:
    """Numbers of fabric repeats of a seam cell.

    Parameters
    ----------
    cell : a 2-periodic spacer Cell (periods along x and y).
    seam_distance : requested seam distance d, mm.
    stitch_length : stitch length s, mm (y period = ``stitches`` x s).
    exact : raise InputError when d is not a whole number of fabric repeats along x (otherwise
        the nearest whole number >= 1 is used and reported as ``seam_distance`` in the result).

    Returns
    -------
    dict: n_x, n_y (repeats), seam_distance (effective d, mm), requested (mm), Lx, Ly (mm).
    """
    try:
        d = float(seam_distance)
    except (TypeError, ValueError):
        raise InputError(f"seam_distance must be a number (mm), got {seam_distance!r}") from None
    if not (math.isfinite(d) and d > 0):
        raise InputError(f"seam_distance must be positive (mm), got {seam_distance!r}")
    fr = cell.frame
    if fr.dim_periodic != 2 or abs(fr.periods[0, 1]) > 1e-9 or abs(fr.periods[1, 0]) > 1e-9:
        raise InputError(f"cell {getattr(cell, 'name', '?')!r}: a seam cell needs a 2-periodic fabric cell "
                         f"with periods along x and y, got {fr.periods.tolist()}")
    Lx, Ly = float(fr.periods[0, 0]), float(fr.periods[1, 1])
    s = float(stitch_length)
    if not (math.isfinite(s) and s > 0):
        raise InputError(f"stitch_length must be positive (mm), got {stitch_length!r}")
    if int(stitches) != stitches or stitches < 1:
        raise InputError(f"stitches must be a positive integer, got {stitches!r}")
    wales = cell.info.get("repeat", (1, 1))[0]
    q = d / Lx
    if q < 0.5:
        raise InputError(f"seam_distance {d:g} mm is less than half the fabric repeat across the wales "
                         f"({Lx:.6g} mm): a seam cell needs at least one repeat")
    n_x = max(1, int(round(q)))
    if exact and abs(q - round(q)) > 1e-6:
        raise InputError(f"seam_distance {d:g} mm is not a multiple of the fabric repeat across the wales "
                         f"({Lx:.6g} mm = {wales} wales of {Lx / wales:.6g} mm): {q:.4g} repeats; "
                         f"nearest: {n_x * Lx:.6g} mm")
    qy = s * stitches / Ly
    if abs(qy - round(qy)) > 1e-6:
        raise InputError(f"stitch_length {s:g} mm is not a whole number of fabric repeats along the wales "
                         f"({Ly:.6g} mm = {cell.info.get('repeat', (1, 1))[1]} courses): {qy:.4g} repeats; "
                         "change courses_per_cm in the cell file")
    return {"n_x": n_x, "n_y": int(round(qy)), "seam_distance": n_x * Lx, "requested": d, "Lx": Lx, "Ly": Ly}


def leg_position(cell, r_stitch: float, ny: int = 40) -> tuple[float, float, float]:
    """Needle-hole position (x_s, y_s) (mm) with the most clearance (mm) between the stitch legs and
    the fabric's yarns: candidates are the wale centres (k + 1/2) w of the repeat and ``ny`` points
    along y. The needle pierces between yarns; the legs then start free of the fabric."""
    f = cell.frame
    Lx, Ly = float(f.periods[0, 0]), float(f.periods[1, 1])
    w = float(cell.info["wale_spacing"])
    T = float(cell.info["thickness"])
    q1 = f.nodes[f.elements[:, 0]]
    d2 = f.nodes[f.elements[:, 1]] + f.shift - q1
    r = f.contact_radius
    xs = (np.arange(int(round(Lx / w))) + 0.5) * w
    ys = np.arange(ny) * (Ly / ny)
    best = (-np.inf, 0.0, 0.0)
    for x in xs:
        for y in ys:
            dmin = np.inf
            for sx in (-1, 0, 1):
                for sy in (-1, 0, 1):
                    P = np.broadcast_to(np.array([x + sx * Lx, y + sy * Ly, 0.0]), q1.shape)
                    D = np.broadcast_to(np.array([0.0, 0.0, T]), q1.shape)
                    dist = segment_distances(P, D, q1, d2)[0]
                    dmin = min(dmin, float((dist - r).min()))
            if dmin > best[0] + 1e-9:
                best = (dmin, float(x), float(y))
    return best[1], best[2], best[0] - float(r_stitch)


def seam_cell(cell, *, seam_distance: float, prestrain=0.0, stitches: int = 1, exact: bool = False,
              elements_per_mm: float = 2.0, leg_elements: int = 4, seam_table: dict | None = None, seams: int = 1):
    """Yarn-level seam cell of a spacer fabric cell (see the module docstring).

    Parameters
    ----------
    cell : spacer Cell with a [parameters.seam] table (stitch_length, yarn) and the stitch yarn type.
    seam_distance : d, mm (rounded to whole fabric repeats across the wales unless ``exact``).
    prestrain : eps0 on every stitch element, or one per seam ((seams,): a strip whose seams were
        sewn at different tensions).
    stitches : stitches along y in the cell (1: one stitch length; 2: a 2-stitch supercell).
    seams : seams in the cell, ``seam_distance`` apart (1: the seam cell; k > 1: a strip of k
        cushions, x period k d; seam i at x_s + i d).
    elements_per_mm : elements per mm of the needle and bobbin chains.
    leg_elements : elements per leg (top/bottom surface to the interlock).

    Returns
    -------
    (frame, info): info has groups ({name: (m,) bool}, incl. "stitch"), layer ((m,) "top" |
    "bottom" | "pile" | "stitch"), element_source ((m_fabric,) the fabric cell's element each fabric
    element copies), thickness, seam_x (x of the seam line), seam_distance (effective),
    requested_seam_distance, stitch_length, n_x, n_y, stitch_yarn (yarn id), stitch_EA (N, one strand),
    legs ((m,) bool), needle_nodes, bobbin_nodes, interlock_nodes, leg_top_nodes, leg_bottom_nodes.
    """
    seam = seam_table if seam_table is not None else (cell.parameters or {}).get("seam")
    if not isinstance(seam, dict):
        raise InputError(f"cell {getattr(cell, 'name', '?')!r}: no [parameters.seam] table "
                         "(stitch_length, prestrain, yarn)")
    s = float(seam.get("stitch_length", 4.0))
    yname = seam.get("yarn", "stitch")
    if yname not in cell.yarns:
        raise InputError(f"[parameters.seam] yarn {yname!r} is not a yarn type of cell "
                         f"{getattr(cell, 'name', '?')!r} (known: {sorted(cell.yarns)})")
    if int(seams) != seams or seams < 1:
        raise InputError(f"seams must be a positive integer, got {seams!r}")
    seams = int(seams)
    eps_seam = np.atleast_1d(np.asarray(prestrain, dtype=float))
    if eps_seam.shape == (1,):
        eps_seam = np.full(seams, eps_seam[0])
    if eps_seam.shape != (seams,):
        raise InputError(f"prestrain must be one number or one per seam ({seams}), got {np.shape(prestrain)}")
    for i, e in enumerate(eps_seam):
        if not (math.isfinite(e) and 0.0 <= e < 1.0):
            raise InputError(f"prestrain of seam {i + 1} must lie in [0, 1), got {e!r}")
    til = seam_tiling(cell, seam_distance, s, stitches=stitches, exact=exact)
    base = cell.frame
    bond = (cell.groups or {}).get("interlacing")
    fab, node_copy, elem_copy, elem_src = tile_frame(base, til["n_x"] * seams, til["n_y"], bond=bond)
    T = float(cell.info["thickness"])
    w = float(cell.info["wale_spacing"])
    yt = cell.yarns[yname]
    r_s = float(yt.radius)
    E_s, nu_s = float(yt.E), float(yt.nu)
    Ly_cell = til["n_y"] * til["Ly"]
    x_s, y_s, clearance = leg_position(cell, r_s)
    # ---- stitch nodes: per seam a needle and a bobbin chain along y and the legs at the stitch points
    n_chain = max(2, int(math.ceil(s * elements_per_mm)))
    n_chain_tot = n_chain * int(stitches)
    yc = y_s + np.arange(n_chain_tot) * (Ly_cell / n_chain_tot)
    n0 = fab.n_nodes
    d_eff = float(til["seam_distance"])
    nl = max(1, int(leg_elements))
    pts, els, imgs, leg, eps_el = [], [], [], [], []
    needles, bobbins, inter, leg_top, leg_bot = [], [], [], [], []
    nxt = n0
    for j in range(seams):
        xj = x_s + j * d_eff
        needle = nxt + np.arange(n_chain_tot)
        bobbin = needle + n_chain_tot
        nxt += 2 * n_chain_tot
        needles.append(needle)
        bobbins.append(bobbin)
        pts += [np.column_stack([np.full(n_chain_tot, xj), yc, np.full(n_chain_tot, T + r_s)]),
                np.column_stack([np.full(n_chain_tot, xj), yc, np.full(n_chain_tot, -r_s)])]
        for chain in (needle, bobbin):
            im = np.zeros((n_chain_tot, 2), dtype=np.int64)
            im[-1, 1] = 1
            els.append(np.column_stack([chain, np.roll(chain, -1)]))
            imgs.append(im)
            leg.append(np.zeros(n_chain_tot, dtype=bool))
        for k in range(int(stitches)):
            top = needle[k * n_chain]
            bot = bobbin[k * n_chain]
            y = yc[k * n_chain]
            # interior leg nodes: needle leg from top down to T/2, bobbin leg from bottom up to T/2
            zt = (T + r_s) - (T / 2 + r_s) * np.arange(1, nl + 1) / nl          # ends at T/2
            zb = -r_s + (T / 2 + r_s) * np.arange(1, nl) / nl                    # interior of bobbin leg
            idx_t = nxt + np.arange(nl)
            idx_b = nxt + nl + np.arange(nl - 1)
            nxt += 2 * nl - 1
            pts.append(np.column_stack([np.full(nl, xj), np.full(nl, y), zt]))
            pts.append(np.column_stack([np.full(nl - 1, xj), np.full(nl - 1, y), zb]))
            mid = idx_t[-1]
            for ch in (np.r_[top, idx_t], np.r_[bot, idx_b, mid]):
                els.append(np.column_stack([ch[:-1], ch[1:]]))
                imgs.append(np.zeros((len(ch) - 1, 2), dtype=np.int64))
                leg.append(np.ones(len(ch) - 1, dtype=bool))
            inter.append(mid)
            leg_top.append(top)
            leg_bot.append(bot)
        eps_el.append(np.full(sum(len(e) for e in els) - sum(len(e) for e in eps_el), eps_seam[j]))
    s_nodes = np.vstack(pts)
    s_el = np.vstack(els)
    s_img = np.vstack(imgs)
    is_leg = np.concatenate(leg)
    ms = len(s_el)
    sid = int(fab.yarn.max()) + 1
    rad = np.where(is_leg, math.sqrt(2.0) * r_s, r_s)
    ref = np.zeros((ms, 3))
    ref[:, 0] = np.where(is_leg, 1.0, 0.0)
    ref[:, 2] = np.where(is_leg, 0.0, 1.0)
    nodes = np.vstack([fab.nodes, s_nodes])
    fab_fields = fab.element_fields()
    fab_fields["prestrain"] = np.zeros(fab.n_elements)
    stitch_fields = {"semi_axes": np.column_stack([rad, rad]), "E": np.full(ms, E_s), "nu": np.full(ms, nu_s),
                     "yarn": np.full(ms, sid), "ref": ref, "contact_radius": np.full(ms, r_s),
                     "prestrain": np.concatenate(eps_el), "strain_limit": np.full(ms, float(yt.strain_limit))}
    frame = Frame(nodes, np.vstack([fab.elements, s_el]), periods=fab.periods,
                  images=np.vstack([fab.images, s_img]), **stack_fields(fab_fields, stitch_fields))
    m_f = fab.n_elements
    groups = {}
    for g, mask in (cell.groups or {}).items():
        groups[g] = np.r_[np.asarray(mask, bool)[elem_src], np.zeros(ms, dtype=bool)]
    groups["stitch"] = np.r_[np.zeros(m_f, dtype=bool), np.ones(ms, dtype=bool)]
    layer = np.r_[np.asarray(cell.info["layer"])[elem_src], np.full(ms, "stitch")]
    info = {
        "generator": "seam", "groups": groups, "layer": layer, "thickness": T,
        "seam_x": x_s, "seam_y": y_s, "leg_clearance": clearance, "seam_distance": til["seam_distance"],
        "requested_seam_distance": til["requested"],
        "stitch_length": s, "stitches": int(stitches), "n_x": til["n_x"], "n_y": til["n_y"],
        "stitch_yarn": sid, "stitch_radius": r_s, "stitch_EA": E_s * math.pi * r_s ** 2,
        "legs": np.r_[np.zeros(m_f, dtype=bool), is_leg],
        "needle_nodes": np.concatenate(needles), "bobbin_nodes": np.concatenate(bobbins),
        "interlock_nodes": np.array(inter), "leg_top_nodes": np.array(leg_top), "leg_bottom_nodes": np.array(leg_bot),
        "fabric_nodes": n0, "fabric_elements": m_f, "element_source": elem_src,
        "prestrain": float(eps_seam[0]) if seams == 1 else eps_seam, "seams": seams,
        "seam_xs": x_s + d_eff * np.arange(seams),
        "wale_spacing": w, "course_spacing": cell.info.get("course_spacing"),
    }
    return frame, info
