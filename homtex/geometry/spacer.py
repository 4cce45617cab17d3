"""Warp-knitted spacer fabric cells from lapping notation.

A spacer fabric knitted on a double-needle-bar raschel machine: a top layer
(front needle bar), a bottom layer (back needle bar) and pile monofilaments that
knit alternately on both bars and so run between the layers. Each guide bar is
described by its lapping in the usual chain notation, a threading, the needle bar
(or bars) it knits on and a yarn type; the repeat of the pattern is the periodic
cell. :func:`spacer_fabric` builds the beam :class:`~homtex.Frame`;
:func:`build_cell` is the same for a cell file (``generator = "spacer"``).

Coordinates (mm): x across the wales (needle direction), y along the wales
(course / machine direction), z through the thickness. The fabric lies between
z = 0 (outer surface of the bottom layer) and z = thickness (outer surface of the
top layer): the outermost yarn surfaces touch those planes exactly.

Lapping notation (documented convention)
----------------------------------------
A lapping is a list of course tokens separated by ``/`` and closed by ``//``,
e.g. ``"1-0/0-1//"``. Numbers are guide positions in the gaps between needles:
needle k stands between gaps k and k + 1 (x = (k + 1/2) * wale spacing, gap g at
x = g * wale spacing).

* Two-number tokens ``a-b`` (single needle bar): the bar knits on its ``bed``
  ("front" = top layer, "back" = bottom layer). ``a != b`` is an overlap: a loop on
  needle min(a, b), the yarn entering on the side of gap a and leaving on the side
  of gap b (only single-needle overlaps, |a - b| = 1). ``a == b`` is no overlap: the
  yarn is laid in at gap a (inlay, e.g. ``0-0/2-2//``).
* Four-number tokens ``a-b-c-d`` (double needle bar): ``a-b`` is the lap on the
  front needle bar, ``c-d`` the lap on the back needle bar in the same machine
  course; an equal pair means that bar is not lapped. Pile bars (``bed = "both"``)
  must use this form, e.g. ``"1-0-3-4/3-4-1-0//"``: in course 0 a loop on needle 0
  of the front bar, then one on needle 3 of the back bar, and so on.
* The back needle bar knits half a machine cycle after the front bar: its loops
  lie ``back_shift`` (default 1/2) of a course spacing further along y, which gives
  the pile legs their inclination along y; their inclination along x comes from the
  needle offset between the front and the back lap.
* The lapping repeat is the list of tokens; the cell repeat along y is the least
  common multiple of the bars' repeats, along x that of their threading repeats.

Threading: ``"full"`` (every guide threaded), ``"1-in 1-out"`` (= ``"x."``) or a
pattern string of ``x`` (threaded) and ``.`` (empty) guides, one per wale.

Yarn centerlines
----------------
Each yarn is a smooth curve (centripetal Catmull-Rom spline, periodic up to the
translation of one repeat along y) through control points:

* a loop of a knitting (ground) bar: foot (technical back of the layer), leg, two
  head points (outermost, touching the fabric surface), leg, foot; the underlap to
  the next loop runs on the technical back;
* an inlay course: the yarn lies in gap a (two points, from ``inlay_from`` to
  ``inlay_to`` of a course spacing) between the loop legs and the underlaps, and
  crosses to its next gap halfway between the rows of pile loops;
* a pile loop: the monofilament is plated inside the ground loop of the same
  needle: it rises below the layer, crosses the needle just inside the ground loop
  head (above the inlays, which hold it) and descends again; between a visit of the
  top and one of the bottom layer the pile leg is straight, split into
  ``pile_segments`` segments.

The depth of each level below the outer surface follows from the yarn radii
(see :func:`layer_levels`); yarns of one layer are stacked with a clearance factor
so that they touch without overlapping where the template is exact. Overlaps that
remain are reported by :func:`yarn_overlaps` (and by a warning at creation); they
are not hidden, the contact solver relaxes them.

Each control segment (between consecutive control points) is split into
``elements_per_segment`` beams (the resolution parameter). Every yarn has its own
yarn id; the returned info maps yarn systems (bar ``system`` names, default the bar
name) to element masks.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from ..errors import CellError, InputError
from ..model.frame import Frame
from ..model.sections import YarnType, yarn_fields
from ..validate import check_int, check_keys, check_size, get_int, get_number, get_str, get_table
from .curves import catmull_rom_periodic, overlap_summary, reference_vectors, wrap_chain, yarn_overlaps
from .lapping import Bar, as_bar, lcm, parse_lapping, parse_threading

__all__ = ["INCH", "MAX_ELEMENTS_PER_SEGMENT", "MAX_PILE_SEGMENTS", "SHAPE_DEFAULTS", "build_cell", "layer_levels",
           "spacer_fabric"]

INCH = 25.4  # mm

#: default shape parameters of the loop templates (fractions of wale / course spacing)
SHAPE_DEFAULTS = {
    "loop_half_width": 0.30,   # ground loop legs at x_n +- this * wale spacing
    "head_half_width": 0.15,   # ground loop head points at x_n +- this * wale spacing
    "foot": -0.15,             # y of loop feet, fraction of a course spacing after the course line
    "leg": 0.30,               # y of the loop legs' middle points
    "head": 0.65,              # y of the loop head
    "pile_half_width": 0.10,   # pile loop at x_n +- this * wale spacing
    "pile": 0.30,              # y of the pile loop (centre of the ground loop)
    "inlay_from": -0.18,        # an inlay lies in its gap from this fraction of a course ...
    "inlay_to": 0.42,          # ... to this one, then crosses to its next gap between the pile loops
    "pile_stagger": 0.10,      # pile loop enters at y - this and leaves at y + this (course spacings)
    "back_shift": 0.5,         # back needle bar courses lie this much further along y
    "clearance": 1.05,         # stacking clearance factor on radii sums
    "pile_bow": 0.0,           # pile legs bow sideways (x) by this fraction of their length (alternating sign)
}


# ----------------------------------------------------------------------------------------


# ----------------------------------------------------------------------------------------
# geometry helpers
def layer_levels(r_ground: float, r_inlay: float, r_pile: float, clearance: float = 1.05) -> dict:
    """Depths (mm, below the outer surface of a layer) of the yarn levels of a layer.

    head: ground loop heads (outermost, depth = r_ground so the surface is flush);
    pile: pile loop crossing; inlay: inlay yarns; leg: middle of the ground loop legs;
    foot: loop feet and underlaps (technical back); low: where pile legs leave the layer.
    Consecutive levels are ``clearance * (r1 + r2)`` apart.
    """
    c = clearance
    d = {"head": r_ground}
    d["pile"] = d["head"] + c * (r_ground + r_pile)
    d["inlay"] = d["pile"] + c * (r_pile + r_inlay)
    d["leg"] = d["inlay"] - c * (r_inlay + r_ground)
    d["foot"] = d["inlay"] + c * (r_inlay + r_ground)
    d["low"] = d["foot"] + c * (r_ground + r_pile)
    if r_ground == 0.0:  # a layer with pile loops only: the pile is outermost
        shift = d["pile"] - r_pile
        d = {k: v - shift for k, v in d.items()}
    return d




@dataclass
class _YarnPlan:
    bar: Bar
    guide: int
    courses: list
    role: str  # "ground", "inlay", "pile"
    points: list = field(default_factory=list)     # control points (global, unwrapped)
    nseg: list = field(default_factory=list)       # elements factor per segment (number of sub-segments)


@dataclass
class _Loops:
    """Control-point templates of the loops in one cell: w, cs wale and course spacing (mm), T
    thickness (mm), sh shape parameters, levels {"front"/"back": depths} (:func:`layer_levels`)."""

    w: float
    cs: float
    T: float
    sh: dict
    levels: dict

    def to_global(self, lay, pts):
        """(x, y, depth) in a layer -> global (x, y, z)."""
        pts = np.asarray(pts, float)
        out = pts.copy()
        if lay == "front":
            out[:, 2] = self.T - pts[:, 2]
        else:
            out[:, 1] = pts[:, 1] + self.sh["back_shift"] * self.cs
        return out

    def ground(self, lay, needle, side, y0):
        sh, cs, lv = self.sh, self.cs, self.levels[lay]
        xn = (needle + 0.5) * self.w
        hl, hh = sh["loop_half_width"] * self.w, sh["head_half_width"] * self.w
        f = np.array([
            [xn + side * hl, y0 + sh["foot"] * cs, lv["foot"]],
            [xn + side * hl, y0 + sh["leg"] * cs, lv["leg"]],
            [xn + side * hh, y0 + sh["head"] * cs, lv["head"]],
            [xn - side * hh, y0 + sh["head"] * cs, lv["head"]],
            [xn - side * hl, y0 + sh["leg"] * cs, lv["leg"]],
            [xn - side * hl, y0 + sh["foot"] * cs, lv["foot"]],
        ])
        return self.to_global(lay, f)

    def pile(self, lay, needle, side, y0):
        sh, cs, lv = self.sh, self.cs, self.levels[lay]
        xn = (needle + 0.5) * self.w
        hp = sh["pile_half_width"] * self.w
        y = y0 + sh["pile"] * cs
        dy = sh["pile_stagger"] * cs
        f = np.array([
            [xn + side * hp, y - dy, lv["low"]],
            [xn + side * hp, y - dy, lv["pile"]],
            [xn - side * hp, y + dy, lv["pile"]],
            [xn - side * hp, y + dy, lv["low"]],
        ])
        return self.to_global(lay, f)

    def inlay(self, lay, gap, y0):
        d = self.levels[lay]["inlay"]
        sh, cs = self.sh, self.cs
        return self.to_global(lay, [[gap * self.w, y0 + sh["inlay_from"] * cs, d],
                                    [gap * self.w, y0 + sh["inlay_to"] * cs, d]])


#: largest resolution of a spacer cell: beams per control segment and segments per pile leg. At
#: the limits a pile leg of the 20 mm cell has 5000 beams 4 um long (40x shorter than the yarn is
#: thick, far beyond what beam theory or the convergence studies need); a cell file asking for
#: more is refused before anything is built
MAX_ELEMENTS_PER_SEGMENT = 50
MAX_PILE_SEGMENTS = 100


def _check_numbers(gauge, courses_per_cm, thickness, elements_per_segment, pile_segments, shape):
    """Validated (gauge, courses/cm, thickness, elements per segment, pile segments, shape)."""
    try:
        gauge = float(gauge)
        cpc = float(courses_per_cm)
        T = float(thickness)
    except (TypeError, ValueError) as exc:
        raise InputError(f"gauge, courses_per_cm and thickness must be numbers: {exc}") from None
    for nm, v in (("gauge", gauge), ("courses_per_cm", cpc), ("thickness", T)):
        if not (np.isfinite(v) and v > 0):
            raise InputError(f"{nm} must be positive and finite, got {v}")
    eps = check_int(elements_per_segment, "elements_per_segment", ge=1, le=MAX_ELEMENTS_PER_SEGMENT)
    nleg = check_int(pile_segments, "pile_segments", ge=1, le=MAX_PILE_SEGMENTS)
    sh = dict(SHAPE_DEFAULTS)
    if shape:
        unknown = sorted(set(shape) - set(SHAPE_DEFAULTS))
        if unknown:
            raise InputError(f"shape: unknown key(s) {unknown}; known: {sorted(SHAPE_DEFAULTS)}")
        sh.update({k: float(v) for k, v in shape.items()})
    return gauge, cpc, T, eps, nleg, sh


def _parse_bars(bars, yarns):
    """(bars, laps by bar, threading by bar, course repeat C, wale repeat W)."""
    if isinstance(bars, dict):
        bar_list = [as_bar(k, v) for k, v in bars.items()]
    else:
        bar_list = [as_bar(getattr(b, "name", None) or (b.get("name") if isinstance(b, dict) else f"bar{i}"), b)
                    for i, b in enumerate(bars)]
    if not bar_list:
        raise InputError("a spacer fabric needs at least one guide bar")
    names = [b.name for b in bar_list]
    if len(set(names)) != len(names):
        raise InputError(f"bar names must be unique, got {names}")
    parsed, threads = {}, {}
    for b in bar_list:
        if b.yarn not in yarns:
            raise InputError(f"bar {b.name!r}: yarn {b.yarn!r} is not defined (known yarns: {sorted(yarns)})")
        parsed[b.name] = parse_lapping(b.lapping, b.name, b.bed)
        threads[b.name] = parse_threading(b.threading, b.name)
    C = lcm(len(v) for v in parsed.values())
    W = lcm(len(v) for v in threads.values())
    return bar_list, parsed, threads, C, W


def _role(b, parsed):
    if b.bed == "both":
        return "pile"
    pairs = [c.front if b.bed == "front" else c.back for c in parsed[b.name]]
    return "ground" if any(p[0] != p[1] for p in pairs) else "inlay"


def _levels(bar_list, parsed, yarns, clearance):
    """Depths of the yarn levels of each layer from the largest radius per layer and role."""
    rmax = {}
    for b in bar_list:
        r = yarns[b.yarn].rc
        role = _role(b, parsed)
        for lay in (("front", "back") if role == "pile" else (b.bed,)):
            rmax[(lay, role)] = max(rmax.get((lay, role), 0.0), r)
    return {lay: layer_levels(rmax.get((lay, "ground"), 0.0), rmax.get((lay, "inlay"), 0.0),
                              rmax.get((lay, "pile"), 0.0), clearance) for lay in ("front", "back")}


def _plans(bar_list, parsed, threads, C, W, loops: _Loops, nleg: int, Ly: float) -> list:
    """Control points of every yarn: loops, inlays and straight (bowed) pile legs between layers."""
    sh, cs = loops.sh, loops.cs
    plans = []
    for b in bar_list:
        role = _role(b, parsed)
        thr = threads[b.name]
        courses = parsed[b.name] * (C // len(parsed[b.name]))
        for g in range(W):
            if not thr[g % len(thr)]:
                continue
            plan = _YarnPlan(bar=b, guide=g, courses=courses, role=role)
            pts, lays = [], []
            for c, cl in enumerate(courses):
                y0 = c * cs
                for lay in ("front", "back"):
                    pair = getattr(cl, lay)
                    if pair is None:
                        continue
                    a, bb = pair[0] + g, pair[1] + g
                    if a == bb:
                        pts.append(loops.inlay(lay, a, y0))
                    else:
                        side = 1.0 if a > bb else -1.0
                        needle = min(a, bb)
                        pts.append(loops.pile(lay, needle, side, y0) if role == "pile"
                                   else loops.ground(lay, needle, side, y0))
                    lays.append(lay)
            # assemble with straight pile legs between visits of different layers
            closing = np.array([0.0, Ly, 0.0])
            allp, nseg = [], []
            nv = len(pts)
            for v in range(nv):
                blk = pts[v]
                allp.append(blk)
                nseg.extend([1] * len(blk))
                if lays[(v + 1) % nv] != lays[v]:
                    start = blk[-1]
                    end = pts[(v + 1) % nv][0] + (closing if v == nv - 1 else 0.0)
                    tt = np.arange(1, nleg)[:, None] / nleg
                    leg = start + tt * (end - start)
                    sign = 1.0 if (v % 2 == 0) else -1.0
                    leg[:, 0] += sign * sh["pile_bow"] * np.linalg.norm(end - start) * np.sin(np.pi * tt[:, 0])
                    allp.append(leg)
                    nseg.extend([1] * (nleg - 1))
            plan.points = np.vstack(allp)
            plan.nseg = np.array(nseg, dtype=np.int64)
            plans.append(plan)
    return plans


def _discretise(plans, eps: int, periods, Ly: float):
    """Nodes, elements, images, yarn id per element and control-point flags of all yarns."""
    node_blocks, el_blocks, img_blocks, yarn_ids, ctrl_blocks = [], [], [], [], []
    n0 = 0
    for yid, plan in enumerate(plans):
        nper = plan.nseg * eps
        samples = catmull_rom_periodic(plan.points, np.array([0.0, Ly, 0.0]), nper)
        wrapped, el, im = wrap_chain(samples, periods, np.array([0, 1]))
        is_ctrl = np.zeros(len(samples), dtype=bool)
        is_ctrl[np.cumsum(nper) - nper] = True      # the same points at every resolution
        ctrl_blocks.append(is_ctrl)
        node_blocks.append(wrapped)
        el_blocks.append(el + n0)
        img_blocks.append(im)
        yarn_ids.append(np.full(len(el), yid))
        n0 += len(wrapped)
    return (np.vstack(node_blocks), np.vstack(el_blocks), np.vstack(img_blocks), np.concatenate(yarn_ids),
            np.concatenate(ctrl_blocks))


def _fit_thickness(nodes, elements, rc_el, T):
    """Affine map of z (in place) so that the outer yarn surfaces sit at 0 and T exactly."""
    rc_node = np.zeros(len(nodes))
    rc_node[elements[:, 0]] = rc_el
    for _ in range(3):
        lo = np.argmin(nodes[:, 2] - rc_node)
        hi = np.argmax(nodes[:, 2] + rc_node)
        z_lo, z_hi = nodes[lo, 2], nodes[hi, 2]
        target_lo, target_hi = rc_node[lo], T - rc_node[hi]
        if target_hi <= target_lo:
            raise InputError(f"thickness {T} mm is too small for the layers' yarns "
                             f"(the two layers alone need {z_hi - z_lo + rc_node[lo] + rc_node[hi]:.3g} mm)")
        alpha = (target_hi - target_lo) / (z_hi - z_lo)
        nodes[:, 2] = target_lo + alpha * (nodes[:, 2] - z_lo)


def _bonds(plans, nodes, elements, yarn, rc_el, is_control, periods, T, levels, bond_distance):
    """Interlacing bonds: (a, b) node pairs and images from pile / inlay control points inside a
    layer to the nearest ground-loop control point closer than ``bond_distance`` (bonds join
    control points only: the interlacings of the knit, the same at every resolution; bonding
    every node within reach made the cell stiffer with refinement)."""
    none = (np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64), np.zeros((0, 2), dtype=np.int64))
    if not bond_distance > 0:
        return none
    Lx, Ly = periods[0, 0], periods[1, 1]
    role_y = np.array([p.role for p in plans])
    node_yarn = np.empty(len(nodes), dtype=np.int64)
    node_yarn[elements[:, 0]] = yarn
    zc = 0.5 * T
    in_layer = np.abs(nodes[:, 2] - zc) > zc - levels["front"]["low"] - 1e-9
    ground = in_layer & is_control & (role_y[node_yarn] == "ground")
    other = in_layer & is_control & (role_y[node_yarn] != "ground")
    gi, oi = np.flatnonzero(ground), np.flatnonzero(other)
    if not (len(gi) and len(oi)):
        return none
    box = np.array([Lx, Ly, 1e6])
    tree = cKDTree(np.mod(nodes[gi], box), boxsize=box)
    dist, j = tree.query(np.mod(nodes[oi], box))
    ok = dist < bond_distance
    a_n, b_n = oi[ok], gi[j[ok]]
    diff = nodes[b_n] - nodes[a_n]
    img = -np.round(diff[:, :2] / np.array([Lx, Ly])).astype(np.int64)
    keep = np.linalg.norm(diff + img @ periods, axis=1) > 1e-9
    return a_n[keep], b_n[keep], img[keep]


def spacer_fabric(gauge: float, courses_per_cm: float, thickness: float, bars, yarns: dict, *,
                  elements_per_segment: int = 4, pile_segments: int = 4, shape: dict | None = None,
                  check_overlaps: bool = True, bond_distance: float = 0.0) -> tuple[Frame, dict]:
    """A periodic spacer fabric cell from its knitting description.

    Parameters
    ----------
    gauge : needles per inch (wale spacing 25.4 / gauge mm).
    courses_per_cm : courses per cm (course spacing 10 / courses_per_cm mm).
    thickness : plate distance, mm: the outer yarn surfaces lie at z = 0 and z = thickness.
    bars : list of :class:`Bar` (or dicts with name, lapping, yarn, bed, threading, system),
        or a dict name -> table.
    yarns : dict name -> :class:`~homtex.YarnType` (the bars' ``yarn`` names).
    elements_per_segment : beams per control segment (resolution), 1 .. 50.
    pile_segments : control segments along each pile leg between the layers, 1 .. 100.
    shape : overrides of :data:`SHAPE_DEFAULTS`.
    check_overlaps : compute :func:`yarn_overlaps` and warn if any.
    bond_distance : mm; > 0 adds interlacing bonds: a connector beam (ground yarn's material,
        its smaller semi-axis as radius, yarn id of the pile/inlay yarn, contact radius of the ground yarn)
        from every pile/inlay node inside a layer to its nearest ground-loop node closer than
        this. Frictionless contact alone leaves knitted loops free to slide apart; the bonds
        stand for the interlocking of the loops (a modelling simplification). Group
        "interlacing" in info["groups"].

    Returns
    -------
    (frame, info) with info keys: groups ({system: (m,) bool}), thickness, wale_spacing,
    course_spacing, repeat (wales, courses), periods (2, 3), yarn_bar ({yarn id: bar}),
    yarn_group ({yarn id: system}), layer ((m,) str array "top"/"bottom"/"pile"),
    levels ({"top"/"bottom": depths}), overlaps (structured array), yarn_types (dict).
    """
    gauge, cpc, T, eps, nleg, sh = _check_numbers(gauge, courses_per_cm, thickness, elements_per_segment,
                                                  pile_segments, shape)
    w = INCH / gauge
    cs = 10.0 / cpc
    bar_list, parsed, threads, C, W = _parse_bars(bars, yarns)
    # every yarn visits at most two layers per course: <= 2 loops of 6 points and 2 pile legs
    n_yarns = sum(sum(1 for g in range(W) if threads[b.name][g % len(threads[b.name])]) for b in bar_list)
    check_size(n_yarns * C * 2 * (6 + nleg) * eps, f"a spacer cell of {W} wales x {C} courses")
    Lx, Ly = W * w, C * cs
    periods = np.array([[Lx, 0.0, 0.0], [0.0, Ly, 0.0]])
    levels = _levels(bar_list, parsed, yarns, sh["clearance"])
    plans = _plans(bar_list, parsed, threads, C, W, _Loops(w=w, cs=cs, T=T, sh=sh, levels=levels), nleg, Ly)
    nodes, elements, images, yarn, is_control = _discretise(plans, eps, periods, Ly)
    types = [yarns[p.bar.yarn] for p in plans]
    fields = yarn_fields(types, yarn)
    _fit_thickness(nodes, elements, fields["contact_radius"], T)
    n_yarn_el = len(elements)
    frame0 = Frame(nodes, elements, periods=periods, images=images, yarn=yarn,
                   ref=reference_vectors(nodes, elements, images @ periods),
                   **{k: v for k, v in fields.items() if k not in ("bending_factor", "torsion_factor", "strain_limit")})
    a_n, b_n, img = _bonds(plans, nodes, elements, yarn, fields["contact_radius"], is_control, periods, T, levels,
                           bond_distance)
    if len(a_n):
        # a bond: the ground yarn's material, its smaller semi-axis as radius, its contact radius
        node_yarn = np.empty(len(nodes), dtype=np.int64)
        node_yarn[elements[:, 0]] = yarn
        gy = node_yarn[b_n]
        bond = yarn_fields(types, gy)
        rb = bond["semi_axes"].min(axis=1)
        bond["semi_axes"] = np.column_stack([rb, rb])
        elements = np.vstack([elements, np.column_stack([a_n, b_n])])
        images = np.vstack([images, img])
        yarn = np.concatenate([yarn, gy])
        fields = {k: np.concatenate([fields[k], bond[k]]) for k in fields}
    frame = Frame(nodes, elements, periods=periods, images=images, yarn=yarn,
                  ref=reference_vectors(nodes, elements, images @ periods), **fields)
    info = _info(plans, bar_list, yarns, frame, elements, yarn, n_yarn_el, T, w, cs, W, C, periods, levels, eps,
                 nleg, sh)
    if check_overlaps:
        ov = yarn_overlaps(frame0)
        info["overlaps"] = ov
        if len(ov):
            warnings.warn(f"spacer fabric: {overlap_summary(ov, yarn_group=info['yarn_group'])} at creation "
                          f"(left for the contact solver to relax)", stacklevel=2)
    return frame, info


def _info(plans, bar_list, yarns, frame, elements, yarn, n_yarn_el, T, w, cs, W, C, periods, levels, eps, nleg,
          sh) -> dict:
    """The generator's info: element groups per yarn system (and bonds), layers, geometry."""
    groups = {}
    is_bond = np.zeros(len(elements), dtype=bool)
    is_bond[n_yarn_el:] = True
    for yid, plan in enumerate(plans):
        g = plan.bar.group
        groups.setdefault(g, np.zeros(len(elements), dtype=bool))
        groups[g] |= (yarn == yid) & ~is_bond
    if is_bond.any():
        groups["interlacing"] = is_bond
    layer_of = {"front": "top", "back": "bottom", "both": "pile"}
    layer = np.array([layer_of[plans[y].bar.bed] for y in yarn])
    layer[is_bond] = np.where(frame.nodes[elements[is_bond, 0], 2] > 0.5 * T, "top", "bottom")
    return {
        "generator": "spacer",
        "groups": groups,
        "thickness": T,
        "wale_spacing": w,
        "course_spacing": cs,
        "repeat": (W, C),
        "periods": periods,
        "yarn_bar": {i: p.bar.name for i, p in enumerate(plans)},
        "yarn_group": {i: p.bar.group for i, p in enumerate(plans)},
        "yarn_guide": {i: p.guide for i, p in enumerate(plans)},
        "layer": layer,
        "levels": {"top": levels["front"], "bottom": levels["back"]},
        "control_points": {i: p.points for i, p in enumerate(plans)},
        "segments": int(sum(len(p.nseg) for p in plans)),
        "elements_per_segment": eps,
        "pile_segments": nleg,
        "bars": {b.name: b for b in bar_list},
        "yarn_types": dict(yarns),
        "yarn_type": {i: p.bar.yarn for i, p in enumerate(plans)},
        "shape": sh,
        "n_bonds": int(is_bond.sum()),
    }


#: keys of a spacer cell's [parameters.seam] table (read by homtex.seam_profile and seam_compression)
SEAM_KEYS = ("stitch_length", "prestrain", "elements_per_mm", "leg_elements", "foundation_prestrain",
             "layer_rigidity", "layer_rigidity_cell", "yarn", "stitch", "tension", "ramp_steps", "method",
             "calibration")


def _check_seam_table(seam: dict, yarns: dict) -> None:
    """Validate [parameters.seam] when the cell is loaded (the seam models read it later)."""
    if not seam:
        return
    t = "parameters.seam"
    check_keys(seam, SEAM_KEYS, t)
    get_number(seam, "stitch_length", t, default=4.0, gt=0, le=100)          # mm
    get_number(seam, "prestrain", t, default=0.0, ge=0, lt=1)
    get_number(seam, "elements_per_mm", t, default=1.0, gt=0, le=100)
    get_int(seam, "leg_elements", t, default=4, ge=1)
    get_number(seam, "foundation_prestrain", t, default=0.0, ge=0, lt=1)
    get_number(seam, "layer_rigidity", t, required=False, gt=0, le=1e9)      # N mm^2 per stitch length
    get_str(seam, "layer_rigidity_cell", t, default="")
    get_number(seam, "tension", t, required=False, ge=0, le=1e4)             # N per thread strand
    get_int(seam, "ramp_steps", t, default=10, ge=1)
    get_str(seam, "calibration", t, default="")
    for key, choices in (("stitch", ("length", "tension")), ("method", ("yarn", "foundation"))):
        v = seam.get(key)
        if v is not None and v not in choices:
            raise CellError(f"{v!r} is not one of {list(choices)}", table=t, key=key)
    name = get_str(seam, "yarn", t, default="stitch")
    if name not in yarns:
        raise CellError(f"no yarn type {name!r} for the stitch; the file defines {sorted(yarns)}", table=t, key="yarn")


def build_cell(parameters: dict, yarns: dict[str, YarnType], resolution: dict) -> tuple[Frame, dict]:
    """Generator entry point for cell files with ``generator = "spacer"``.

    Parameters
    ----------
    parameters : the cell's [parameters] table: gauge (needles/inch), courses_per_cm,
        thickness (mm), bars ({name: {lapping, yarn, bed, threading, system}}), optional
        shape ({key: value}, see :data:`SHAPE_DEFAULTS`); ``seam`` (a table read by
        :func:`homtex.seam_profile`, ignored here).
    yarns : yarn types by name.
    resolution : the [resolution] table: elements_per_segment (default 4, at most 50), pile_segments
        (default 4, at most 100).

    Returns
    -------
    (frame, info) as :func:`spacer_fabric`.
    """
    p = dict(parameters)
    t = "parameters"
    check_keys(p, ("gauge", "courses_per_cm", "thickness", "bars", "shape", "seam", "bond_distance"), t)
    gauge = get_number(p, "gauge", t, gt=0, le=100)               # needles per inch
    cpc = get_number(p, "courses_per_cm", t, gt=0, le=100)
    thickness = get_number(p, "thickness", t, gt=0, le=1000)      # mm
    bond = get_number(p, "bond_distance", t, default=0.0, ge=0, le=100)
    bars = get_table(p, "bars", t)
    seam = get_table(p, "seam", t, required=False)
    for name, spec in bars.items():
        spec = get_table(bars, name, f"{t}.bars")
        if spec.get("yarn") == seam.get("yarn"):
            raise CellError(f"yarn {spec.get('yarn')!r} is the seam's stitch yarn", table=f"{t}.bars.{name}",
                            key="yarn")
        for key in ("lapping", "yarn", "bed", "threading", "system"):
            if key in spec:
                get_str(spec, key, f"{t}.bars.{name}")
    _check_seam_table(seam, yarns)
    shape = get_table(p, "shape", t, required=False)
    for key in shape:
        get_number(shape, key, f"{t}.shape")
    res = dict(resolution or {})
    check_keys(res, ("elements_per_segment", "pile_segments"), "resolution")
    eps = get_int(res, "elements_per_segment", "resolution", default=4, ge=1, le=MAX_ELEMENTS_PER_SEGMENT)
    nleg = get_int(res, "pile_segments", "resolution", default=4, ge=1, le=MAX_PILE_SEGMENTS)
    return spacer_fabric(gauge, cpc, thickness, bars, yarns, elements_per_segment=eps, pile_segments=nleg,
                         shape=shape or None, bond_distance=bond)
