"""The ``weft_knit`` cell generator: a cell file's notation, loop length and yarn -> a periodic
frame of straight-at-rest yarns (:func:`build_cell`), one equivalent yarn per course or N
parallel filaments.

Cell-file keys (``[parameters]``; lengths in mm):

* ``notation`` (array of strings, one per course; :func:`~homtex.geometry.weft_knit.parse_notation`),
  ``needles`` (bed width in needle positions, default the notation's), ``loop_length`` (stitch
  length), ``wale_spacing`` and ``course_spacing`` (optional, both or neither: the loop-geometry
  model scales with the loop length otherwise), ``repeat`` ([courses-direction, wales-direction]
  copies of the pattern in the cell, default [1, 1]), ``yarn`` (the yarn table, default the only one);
* ``[parameters.yarn_model]``: ``filaments`` (N, default 1: the yarn table is the yarn itself),
  ``model`` ("equivalent": one beam with the bundle's axial stiffness N E A_f and the filaments'
  bending and torsion rigidity N E I_f, N G J_f, contact radius of the packed bundle; or
  "filaments": N beams, each its own chain, packed hexagonally around the centerline and in
  contact with each other), ``packing`` (fibre volume fraction of the bundle's section, default
  0.9069, hexagonal), ``gap`` (clearance between neighbouring filaments at creation, share of the
  filament radius, default 0.05), ``density`` (kg/mm^3, optional: the yarn's linear density in tex
  is reported), ``failure_stress`` (MPa, optional: tensile tests flag filaments beyond it);
* ``[parameters.compression]`` (optional, the yarns flatten where they cross;
  :class:`~homtex.model.compression.YarnCompression` data): ``travel`` and ``force`` (a yarn
  compression test between plates: mm after first contact, N), ``diameter`` (mm),
  ``core_fraction`` (hard core / radius, default 0.15), ``contact_length`` (mm, default one
  diameter); or ``shell``, ``stiffness``, ``exponent`` directly;
* ``[resolution] element_length`` (mm, default a tenth of the loop length).

The frame's yarn ids are (course, filament); ``info`` holds the rest state (straight, parallel
transported), the compression law, the loop geometry, the wale (a2, y) and course (a1, x)
directions, the stitches and needle positions of the cell, and the overlaps at creation.
"""

from __future__ import annotations

import logging

import numpy as np

from ..errors import CellError
from ..model.compression import YarnCompression
from ..model.exclusions import arc_exclusions
from ..model.frame import Frame
from ..model.rest import node_frames, straight_rest
from ..validate import check_keys, check_size, get_int, get_list, get_number, get_str, get_table
from .curves import segment_distances
from .weft_knit import course_curve, hex_offsets, knit_geometry, parse_notation, resample

log = logging.getLogger(__name__)

__all__ = ["build_cell", "bundle_axis", "creation_overlaps", "knit_frame", "lay_bundles"]

KEYS = ("notation", "needles", "loop_length", "wale_spacing", "course_spacing", "repeat", "yarn", "yarn_model",
        "compression")
#: the bundle's axis keeps its neighbours this much further off than the outermost filament's offset,
#: for the mitre with which the filaments are laid at its bends (1 / cos(theta / 2) = 1.1 at 49 degrees)
MITRE_ROOM = 1.1
MODEL_KEYS = ("filaments", "model", "packing", "gap", "density", "failure_stress")
COMP_KEYS = ("travel", "force", "diameter", "core_fraction", "contact_length", "shell", "stiffness", "exponent",
             "source")


def _compression(d: dict):
    """The YarnCompression of a [parameters.compression] table (or None)."""
    if not d:
        return None
    t = "parameters.compression"
    check_keys(d, COMP_KEYS, t)
    src = get_str(d, "source", t, default="")
    if "travel" in d or "force" in d:
        travel = get_list(d, "travel", t, gt=0)
        force = get_list(d, "force", t, gt=0)
        return YarnCompression.from_plate_test(travel, force, diameter=get_number(d, "diameter", t, gt=0),
                                               core_fraction=get_number(d, "core_fraction", t, ge=0, lt=1,
                                                                        default=0.15),
                                               contact_length=get_number(d, "contact_length", t, gt=0, required=False),
                                               source=src)
    return YarnCompression(shell=get_number(d, "shell", t, gt=0), stiffness=get_number(d, "stiffness", t, gt=0),
                           exponent=get_number(d, "exponent", t, ge=1, le=20, default=1.0), source=src)


def _yarn_model(d: dict, yarn) -> dict:
    t = "parameters.yarn_model"
    check_keys(d, MODEL_KEYS, t)
    n = get_int(d, "filaments", t, default=1, ge=1)
    model = get_str(d, "model", t, default="equivalent", choices=("equivalent", "filaments"))
    packing = get_number(d, "packing", t, gt=0, le=0.9069, default=0.9069)
    gap = get_number(d, "gap", t, ge=0, le=1, default=0.05)
    density = get_number(d, "density", t, gt=0, required=False)
    failure = get_number(d, "failure_stress", t, gt=0, required=False)
    rf = yarn.rc
    bundle = rf * np.sqrt(n / packing) if n > 1 else rf
    tex = None if density is None else n * np.pi * yarn.a * yarn.b * density * 1e9   # g/km
    return {"filaments": n, "model": model, "packing": packing, "gap": gap, "bundle_radius": float(bundle),
            "filament_radius": float(rf), "tex": tex, "failure_stress": failure}


def knit_frame(pattern, geo: dict, yarn, ym: dict, element_length: float, repeat=(1, 1)) -> tuple:
    """(Frame, course index per element, filament per element) of the knit ``pattern`` with the loop
    geometry ``geo`` (:func:`~homtex.geometry.weft_knit.knit_geometry`), yarn type ``yarn`` and yarn
    model ``ym``, repeated ``repeat`` = (along the courses, along the wales) times."""
    nx, ny = repeat
    C, N = pattern.n_courses, pattern.n_needles
    width = N * geo["pitch"] * nx
    height = C * geo["c"] * ny
    keys = ("pitch", "c", "h", "d", "Z0", "a")
    centre, course_of = [], []
    for q in range(ny):
        for j in range(C):
            cur = course_curve(pattern, j, **{k: geo[k] for k in keys})
            cur = np.vstack([cur + [k * N * geo["pitch"], 0.0, 0.0] for k in range(nx)])
            cur[:, 1] += q * C * geo["c"]
            L = float(np.linalg.norm(np.diff(np.vstack([cur, cur[:1] + [width, 0, 0]]), axis=0), axis=1).sum())
            n_el = max(8 * N * nx, int(np.ceil(L / element_length)))
            centre.append(resample(cur, width, n_el))
            course_of.append(q * C + j)
    periods = np.array([[width, 0.0, 0.0], [0.0, height, 0.0]])
    offs = bundle_offsets(ym)
    nf = len(offs)
    nodes, els, yarn_id, img, crs, fil = [], [], [], [], [], []
    base = 0
    for cid, pts in zip(course_of, centre):
        k = len(pts)
        chain = np.c_[np.arange(k), (np.arange(k) + 1) % k]
        if nf > 1:
            D = node_frames(Frame(pts, chain, radius=1.0, E=1.0, nu=0.3, periods=periods,
                                  images=np.r_[np.zeros((k - 1, 2), int), [[1, 0]]]))
        for f in range(nf):
            p = pts if nf == 1 else pts + offs[f, 0] * D[:, :, 1] + offs[f, 1] * D[:, :, 2]
            nodes.append(p)
            els.append(chain + base)
            img.append(np.r_[np.zeros((k - 1, 2), int), [[1, 0]]])
            yarn_id.append(np.full(k, cid * nf + f))
            crs.append(np.full(k, cid))
            fil.append(np.full(k, f))
            base += k
    if ym["model"] == "filaments" or ym["filaments"] == 1:
        radius, rc, bf, tf = (yarn.a, yarn.b), yarn.rc, yarn.bending_factor, yarn.torsion_factor
    else:
        radius, rc, bf, tf = _equivalent_section(yarn, ym)
    m = sum(len(e) for e in els)
    frame = Frame(np.vstack(nodes), np.vstack(els), semi_axes=np.broadcast_to(radius, (m, 2)), E=yarn.E, nu=yarn.nu,
                  yarn=np.concatenate(yarn_id), periods=periods, images=np.vstack(img), contact_radius=rc,
                  bending_factor=bf, torsion_factor=tf, strain_limit=yarn.strain_limit)
    return frame, np.concatenate(crs), np.concatenate(fil)


def bundle_offsets(ym: dict) -> np.ndarray:
    """(N, 2) filament positions in a yarn's section about its axis (mm; the first one on the
    axis), hexagonally packed with the model's clearance; ((0, 0),) for a yarn of one beam."""
    if ym["model"] != "filaments" or ym["filaments"] == 1:
        return np.zeros((1, 2))
    return hex_offsets(ym["filaments"], 2.0 * ym["filament_radius"] * (1.0 + ym["gap"]))


def _equivalent_section(yarn, ym: dict) -> tuple:
    """(semi-axes, contact radius, bending factor, torsion factor) of one beam standing for N
    filaments: area N A_f, rigidities N E I_f and N G J_f, the packed bundle's radius."""
    n = ym["filaments"]
    r_area = ym["filament_radius"] * np.sqrt(n)
    return (r_area, r_area), ym["bundle_radius"], yarn.bending_factor / n, yarn.torsion_factor / n


def bundle_axis(frame: Frame, info: dict, yarn) -> tuple[Frame, np.ndarray]:
    """The yarns of a filament cell as equivalent beams along their axes, for a start that lays
    the filaments around relaxed axes (:func:`homtex.knits.relax.relax`).

    Returns (Frame of each bundle's axial filament with the bundle's equivalent section and, for
    contact, the radius that holds its packed filaments with their clearance: (nc,) nodes, one
    chain per course; (nc,) the nodes of ``frame`` they are).
    """
    ym = info["yarn_model"]
    e0 = np.flatnonzero(info["filament"] == 0)
    nodes = frame.elements[e0, 0]
    renum = np.full(frame.n_nodes, -1, dtype=np.int64)
    renum[nodes] = np.arange(len(nodes))
    radius, _, bf, tf = _equivalent_section(yarn, ym)
    offs = bundle_offsets(ym)
    # the packed filaments with their clearance, and room for the mitre of lay_bundles at a loop's bends
    envelope = float(MITRE_ROOM * np.hypot(offs[:, 0], offs[:, 1]).max() + ym["filament_radius"] * (1.0 + ym["gap"]))
    axis = Frame(frame.nodes[nodes], renum[frame.elements[e0]], semi_axes=np.broadcast_to(radius, (len(e0), 2)),
                 E=yarn.E, nu=yarn.nu, yarn=info["course"][e0], periods=frame.periods, images=frame.images[e0],
                 contact_radius=envelope, bending_factor=bf, torsion_factor=tf, strain_limit=yarn.strain_limit)
    return axis, nodes


def lay_bundles(frame: Frame, info: dict, axis: Frame, axis_nodes: np.ndarray, x_axis: np.ndarray,
                periods: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every filament laid around its yarn's axis moved to ``x_axis`` (nc, 3, mm; the nodes
    ``axis_nodes`` of ``frame``, the chains of ``axis``) with the lattice ``periods`` (k, 3): each
    filament keeps its generated place in the section, in the axis's parallel-transported material
    frame (untwisted, as the generated bundle). The beams' own nodal rotations are not used: on
    elements as long as a loop's radius they stray from the chords by 20 degrees and lay the
    filaments of one bundle through each other.
    Returns (positions (n, 3) mm, rotations from the generated state (n, 3, 3))."""
    D0 = node_frames(axis)
    D1 = node_frames(Frame(x_axis, axis.elements, radius=1.0, E=1.0, nu=0.3, periods=periods, images=axis.images))
    centre = np.empty(frame.n_nodes, dtype=np.int64)
    course, fil, el = info["course"], info["filament"], frame.elements
    slot = np.full(frame.n_nodes, -1, dtype=np.int64)
    slot[axis_nodes] = np.arange(len(axis_nodes))
    for c in np.unique(course):
        first = el[(course == c) & (fil == 0), 0]
        for f in np.unique(fil[course == c]):
            centre[el[(course == c) & (fil == f), 0]] = slot[first]
    local = np.einsum("nji,nj->ni", D0[centre], frame.nodes - frame.nodes[axis_nodes][centre])
    v = np.einsum("nij,nj->ni", D1[centre], local)
    # mitre: at a node where the axis turns by theta, an offset along the turn grows by 1 / cos(theta / 2)
    # so that each filament's chord runs parallel to the axis's chord at its place in the section
    # (plain offsets bring the filaments on the inside of a tight bend through each other)
    ea = axis.elements
    chord = x_axis[ea[:, 1]] + axis.images @ periods - x_axis[ea[:, 0]]
    chord /= np.linalg.norm(chord, axis=1)[:, None]
    u_out, u_in = np.empty_like(x_axis), np.empty_like(x_axis)
    u_out[ea[:, 0]], u_in[ea[:, 1]] = chord, chord
    turn = u_out - u_in
    s_turn = np.linalg.norm(turn, axis=1)
    b = turn / np.where(s_turn > 0, s_turn, 1.0)[:, None]
    cos_half = np.clip(0.5 * np.linalg.norm(u_out + u_in, axis=1), 0.5, 1.0)
    vb = np.einsum("ni,ni->n", v, b[centre])
    v += (vb * (1.0 / cos_half[centre] - 1.0))[:, None] * b[centre]
    x = x_axis[centre] + v
    Q = np.einsum("nij,nkj->nik", D1, D0)
    return x, np.ascontiguousarray(Q[centre])


def build_cell(parameters: dict, yarns: dict, resolution: dict) -> tuple:
    """The ``weft_knit`` generator (see the module docstring): (Frame, info)."""
    t = "parameters"
    check_keys(parameters, KEYS, t)
    pat = parse_notation(parameters.get("notation"), get_int(parameters, "needles", t, default=0, ge=1) or None)
    name = get_str(parameters, "yarn", t, default=next(iter(yarns)) if len(yarns) == 1 else None)
    if name not in yarns:
        raise CellError(f"unknown yarn {name!r} (yarn tables: {', '.join(yarns)})", table=t, key="yarn")
    yarn = yarns[name]
    ym = _yarn_model(get_table(parameters, "yarn_model", t, required=False), yarn)
    comp = _compression(get_table(parameters, "compression", t, required=False))
    # bounds keep a mistyped number from asking for an unbounded number of elements
    loop = get_number(parameters, "loop_length", t, gt=0, le=1e3)
    rep = get_list(parameters, "repeat", t, shape=(2,), integer=True, default=[1, 1], gt=0)
    if rep.max() > 100:
        raise CellError(f"repeat {rep.tolist()}: at most 100 cells each way", table=t, key="repeat")
    rep = (int(rep[0]), int(rep[1]))
    core = ym["bundle_radius"] - (comp.shell if comp is not None else 0.0)
    if comp is not None and ym["model"] == "equivalent":
        comp.check_radius(ym["bundle_radius"])
    geo = knit_geometry(pat, loop, core_radius=core, wale_spacing=get_number(parameters, "wale_spacing", t, gt=0,
                                                                             le=1e3, required=False),
                        course_spacing=get_number(parameters, "course_spacing", t, gt=0, le=1e3, required=False))
    r = resolution or {}
    check_keys(r, ("element_length",), "resolution")
    h = get_number(r, "element_length", "resolution", gt=loop * 1e-4, le=loop, default=loop / 10.0)
    fil = ym["filaments"] if ym["model"] == "filaments" else 1
    check_size(int(pat.n_courses * pat.n_needles * rep[0] * rep[1] * fil * (loop / h + 8)),
               f"the weft-knit cell (element_length {h:g} mm, repeat {list(rep)})")
    frame, course, fil = knit_frame(pat, geo, yarn, ym, h, rep)
    # the polyline's chords are shorter than the curve: scale the geometry once so that the
    # discretised yarn has the stitch length asked for
    for _ in range(3):
        got = float(frame.length[fil == 0].sum()) / (pat.stitches() * rep[0] * rep[1])
        if abs(got / loop - 1.0) <= 1e-6:
            break
        geo = {k: (v * loop / got if k not in ("a",) else v) for k, v in geo.items()}
        frame, course, fil = knit_frame(pat, geo, yarn, ym, h, rep)
    ov = creation_overlaps(frame, core=None if comp is None else frame.contact_radius - comp.shell)
    summary = ov["summary"]
    if ov["count"]:
        log.info("weft knit cell: %s at creation (the relaxation resolves them%s)", summary,
                 "; compressible shells overlap on purpose" if comp is not None else "")
    info = {"pattern": pat, "geometry": geo, "yarn_model": ym, "compression": comp, "rest": straight_rest(frame),
            "course": course, "filament": fil, "repeat": rep, "overlaps": summary, "n_overlaps": ov["count"],
            "n_core_overlaps": ov["core_count"], "deepest_overlap_mm": ov["deepest"],
            "needles": pat.n_needles * rep[0], "courses": pat.n_courses * rep[1],
            "stitches": pat.stitches() * rep[0] * rep[1], "loop_length": loop, "wale_vector": 1, "course_vector": 0,
            "yarn_type": {int(y): name for y in np.unique(frame.yarn)},
            "groups": {"front": _bed_mask(frame, geo, pat, rep, 1), "back": _bed_mask(frame, geo, pat, rep, -1)}}
    return frame, info


def _bed_mask(frame, geo, pat, rep, sign) -> np.ndarray:
    """(m,) elements whose midpoint lies in a needle position of the bed ``sign`` knitting loops."""
    x = frame.nodes[frame.elements[:, 0]] + 0.5 * frame.element_vectors
    pos = np.floor(np.mod(x[:, 0], pat.n_needles * geo["pitch"]) / geo["pitch"]).astype(int) % pat.n_needles
    beds = np.array([sign in pat.bed[:, i] for i in range(pat.n_needles)])
    return beds[pos]


def creation_overlaps(frame: Frame, *, core=None, tol: float = 1e-9) -> dict:
    """Overlaps of the yarn surfaces in a generated knit cell, periodic images included.

    A course meets copies of itself across the wale lattice vector (a jersey cell has one yarn
    that interlocks with its own image), so same-yarn pairs are told apart by image: a pair is
    left out only where the engine leaves it out (:func:`~homtex.model.exclusions.arc_exclusions`:
    elements sharing a node, or of one yarn closer than 3 r along it, at that image).

    Parameters
    ----------
    frame : the cell's Frame (2-periodic). core : (m,) hard-core radii (mm) of compressible yarns,
        to count the pairs whose cores overlap too (None: no shells). tol : depth below which a
        pair touches rather than overlaps, mm.

    Returns {"count", "deepest" (mm), "core_count", "summary" (one line), "pairs" ((q, 2) elements,
    deepest first), "depth" (q,) mm}.
    """
    from scipy.spatial import cKDTree

    el, d, rc, L = frame.elements, frame.element_vectors, frame.contact_radius, frame.length
    x0 = frame.nodes[el[:, 0]]
    m, k = len(el), frame.dim_periodic
    imgs = np.array(np.meshgrid(*[[-1, 0, 1]] * k, indexing="ij")).reshape(k, -1).T.astype(np.int64)
    h = max(2.0 * float(rc.max()), float(L.mean()) / 4.0)
    per = np.maximum(1, np.ceil(L / h)).astype(np.int64)
    owner = np.repeat(np.arange(m), per)
    frac = (np.arange(len(owner)) - (np.cumsum(per) - per)[owner] + 0.5) / per[owner]
    pts = x0[owner] + frac[:, None] * d[owner]
    tree = cKDTree(pts)
    # image codes (base 3 per lattice vector) of the exclusions, keyed with the element pair
    ptr, ex_e, ex_i = arc_exclusions(frame)
    base = 3 ** np.arange(k)
    ok = np.all(np.abs(ex_i) <= 1, axis=1)
    ex_src = np.repeat(np.arange(m), np.diff(ptr))[ok]
    excluded = (ex_src * m + ex_e[ok]) * 3 ** k + (ex_i[ok] + 1) @ base
    a_all, b_all, q_all = [], [], []
    for q, img in enumerate(imgs):
        sdm = tree.sparse_distance_matrix(cKDTree(pts + img @ frame.periods), h + 2.0 * float(rc.max()),
                                          output_type="coo_matrix")
        a, b = owner[sdm.row], owner[sdm.col]
        key = np.unique(a * m + b)
        a, b = key // m, key % m
        keep = ~np.isin((a * m + b) * 3 ** k + (img + 1) @ base, excluded)
        # each unordered pair once: a < b at any image, a == b at a "positive" image
        first = next((int(v) for v in img if v != 0), 0)
        keep &= (a < b) | ((a == b) & (first > 0))
        a_all.append(a[keep])
        b_all.append(b[keep])
        q_all.append(np.full(int(keep.sum()), q))
    a, b, q = np.concatenate(a_all), np.concatenate(b_all), np.concatenate(q_all)
    dist, _, _ = segment_distances(x0[a], d[a], x0[b] + imgs[q] @ frame.periods, d[b])
    depth = rc[a] + rc[b] - dist
    hit = depth > tol
    a, b, depth, dist = a[hit], b[hit], depth[hit], dist[hit]
    order = np.argsort(-depth, kind="stable")
    a, b, depth, dist = a[order], b[order], depth[order], dist[order]
    n_core = 0 if core is None else int(np.count_nonzero(core[a] + core[b] - dist > tol))
    if len(a) == 0:
        summary = "no overlaps"
    else:
        summary = (f"{len(a)} overlapping segment pairs, deepest {depth[0]:.4g} mm between elements {a[0]} and "
                   f"{b[0]} (yarns {frame.yarn[a[0]]} and {frame.yarn[b[0]]})")
        if core is not None:
            summary += f"; {n_core} of them with overlapping hard cores"
    return {"count": int(len(a)), "deepest": float(depth[0]) if len(a) else 0.0, "core_count": n_core,
            "summary": summary, "pairs": np.column_stack([a, b]), "depth": depth}
