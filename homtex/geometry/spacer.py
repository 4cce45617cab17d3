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

import math
import re
import warnings
from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError
from ..model.frame import Frame
from ..model.sections import YarnType

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
# knitting description
@dataclass(frozen=True)
class Bar:
    """One guide bar.

    name : the bar's name (used in errors and as the default yarn-system name).
    lapping : chain notation, e.g. ``"1-0/0-1//"`` (see the module docstring).
    yarn : name of its yarn type.
    bed : "front" (top layer), "back" (bottom layer) or "both" (pile).
    threading : "full", "1-in 1-out" or a pattern of ``x`` / ``.`` per wale.
    system : yarn-system name for the element groups (default: ``name``).
    """

    name: str
    lapping: str
    yarn: str
    bed: str = "front"
    threading: str = "full"
    system: str | None = None

    @property
    def group(self) -> str:
        return self.system or self.name


@dataclass
class CourseLap:
    """One course of a parsed lapping: laps on the front and back needle bar.

    ``front`` / ``back`` are (a, b) guide positions or None when the bar does not
    visit that layer in this course. ``a == b`` means an inlay at gap a.
    """

    token: str
    front: tuple | None
    back: tuple | None


_TOKEN = re.compile(r"^\d+(-\d+)*$")


def parse_lapping(text: str, bar: str = "bar", bed: str = "front") -> list[CourseLap]:
    """Parse a lapping in chain notation (see the module docstring).

    Parameters
    ----------
    text : e.g. ``"1-0/0-1//"`` or ``"1-0-3-4/3-4-1-0//"``.
    bar : the bar's name (for error messages).
    bed : "front", "back" or "both".

    Returns
    -------
    list of :class:`CourseLap`, one per course of the repeat.

    Raises
    ------
    InputError naming the bar and the offending token.
    """
    if bed not in ("front", "back", "both"):
        raise InputError(f"bar {bar!r}: bed must be 'front', 'back' or 'both', got {bed!r}")
    if not isinstance(text, str):
        raise InputError(f"bar {bar!r}: lapping must be a string like '1-0/0-1//', got {text!r}")
    s = "".join(text.split())
    if not s:
        raise InputError(f"bar {bar!r}: lapping is empty")
    if not s.endswith("//"):
        last = s.rstrip("/").split("/")[-1]
        raise InputError(f"bar {bar!r}: lapping {text!r} does not close its repeat: it must end with "
                         f"'//' after the last course (token {last!r})")
    body = s[:-2]
    if "//" in body:
        extra = body.split("//", 1)[1]
        raise InputError(f"bar {bar!r}: lapping {text!r} has tokens after the end of the repeat '//' "
                         f"(token {extra.split('/')[0]!r}); write one repeat only")
    if not body:
        raise InputError(f"bar {bar!r}: lapping {text!r} has no course token before '//'")
    courses = []
    width = None
    for pos, tok in enumerate(body.split("/")):
        if not tok:
            raise InputError(f"bar {bar!r}: lapping {text!r} has an empty course token at position {pos} "
                             f"(a stray '/')")
        if not _TOKEN.match(tok):
            raise InputError(f"bar {bar!r}: token {tok!r} of lapping {text!r} does not parse: "
                             f"expected guide positions like '1-0' or '1-0-3-4' (non-negative integers "
                             f"joined by '-')")
        nums = [int(v) for v in tok.split("-")]
        if len(nums) not in (2, 4):
            raise InputError(f"bar {bar!r}: token {tok!r} has {len(nums)} numbers; a course is 'a-b' "
                             f"(one needle bar) or 'a-b-c-d' (front lap a-b, back lap c-d)")
        if width is None:
            width = len(nums)
        elif len(nums) != width:
            raise InputError(f"bar {bar!r}: token {tok!r} mixes {len(nums)}-number and {width}-number "
                             f"courses in lapping {text!r}")
        if len(nums) == 2:
            pair = (nums[0], nums[1])
            if bed == "both":
                raise InputError(f"bar {bar!r} (bed 'both') needs double-needle-bar tokens "
                                 f"'front-front-back-back', got token {tok!r}")
            front, back = (pair, None) if bed == "front" else (None, pair)
        else:
            fp, bp = (nums[0], nums[1]), (nums[2], nums[3])
            if bed == "front":
                if bp[0] != bp[1]:
                    raise InputError(f"bar {bar!r} has bed 'front' but token {tok!r} laps the back needle "
                                     f"bar ({bp[0]}-{bp[1]}); use bed = 'both' for a pile bar")
                front, back = fp, None
            elif bed == "back":
                if fp[0] != fp[1]:
                    raise InputError(f"bar {bar!r} has bed 'back' but token {tok!r} laps the front needle "
                                     f"bar ({fp[0]}-{fp[1]}); use bed = 'both' for a pile bar")
                front, back = None, bp
            else:
                front = fp if fp[0] != fp[1] else None
                back = bp if bp[0] != bp[1] else None
                if front is None and back is None:
                    raise InputError(f"bar {bar!r}: pile token {tok!r} laps neither needle bar")
        for p in (front, back):
            if p is not None and abs(p[0] - p[1]) > 1:
                raise InputError(f"bar {bar!r}: token {tok!r} overlaps {abs(p[0] - p[1])} needles "
                                 f"({p[0]}-{p[1]}); only single-needle overlaps (|a - b| = 1) are supported")
        courses.append(CourseLap(tok, front, back))
    if bed == "both":
        for side, layer, other in (("back", "bottom", "front"), ("front", "top", "back")):
            if all(getattr(c, side) is None for c in courses):
                raise InputError(
                    f"bar {bar!r}: pile lapping {text!r} never laps the {side} needle bar, so the pile never "
                    f"reaches the {layer} layer (token {courses[0].token!r} and all others lap only the "
                    f"{other} bar)")
    return courses


def parse_threading(spec: str, bar: str = "bar") -> np.ndarray:
    """Threading pattern -> bool array (one per guide/wale of its repeat)."""
    if not isinstance(spec, str):
        raise InputError(f"bar {bar!r}: threading must be a string ('full', '1-in 1-out' or 'x.' pattern), "
                         f"got {spec!r}")
    key = spec.strip().lower().replace("_", "-").replace(" ", "")
    if key in ("full", "all"):
        return np.array([True])
    if key in ("1-in1-out", "1in1out", "half"):
        return np.array([True, False])
    bad = [ch for ch in spec.strip() if ch not in "x.|-1"]
    if bad or not spec.strip():
        raise InputError(f"bar {bar!r}: threading {spec!r} is not 'full', '1-in 1-out' or a pattern of 'x' "
                         f"(threaded) and '.' (empty) guides (bad character {bad[0] if bad else ''!r})")
    pat = np.array([ch in "x|1" for ch in spec.strip()])
    if not pat.any():
        raise InputError(f"bar {bar!r}: threading {spec!r} threads no guide")
    return pat


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
    (largest first); each pair once.
    """
    from scipy.spatial import cKDTree

    x0 = frame.nodes[frame.elements[:, 0]]
    d = frame.element_vectors
    m = frame.n_elements
    rc = frame.contact_radius
    mid = x0 + 0.5 * d
    k = frame.dim_periodic
    imgs = np.array(np.meshgrid(*[[-1, 0, 1]] * k, indexing="ij")).reshape(k, -1).T if k else np.zeros((1, 0))
    imgs = imgs.astype(np.int64)
    shifts = imgs @ frame.periods if k else np.zeros((1, 3))
    reach = float(frame.length.max() + 2.0 * rc.max())
    tree = cKDTree(mid)
    ea, eb, ei = [], [], []
    for q, sh in enumerate(shifts):
        # sparse distance matrix between the original midpoints and the shifted ones
        other = cKDTree(mid + sh)
        sdm = tree.sparse_distance_matrix(other, reach, output_type="coo_matrix")
        a, b = sdm.row.astype(np.int64), sdm.col.astype(np.int64)
        ea.append(a)
        eb.append(b)
        ei.append(np.full(len(a), q))
    a = np.concatenate(ea)
    b = np.concatenate(eb)
    qi = np.concatenate(ei)
    # each unordered pair once: a < b, or a == b with a "positive" image
    img = imgs[qi]
    zero = np.all(img == 0, axis=1)
    if k:
        first = np.zeros(len(img), dtype=np.int64)
        for c in range(k - 1, -1, -1):
            first = np.where(img[:, c] != 0, img[:, c], first)
    else:
        first = np.zeros(len(img), dtype=np.int64)
    keep = (a < b) | ((a == b) & ~zero & (first > 0))
    a, b, qi = a[keep], b[keep], qi[keep]
    # same yarn: exclude neighbours along the yarn
    same = frame.yarn[a] == frame.yarn[b]
    if same.any():
        L = frame.length
        cum = np.cumsum(L) - L                     # arc length at the start of each element
        _, first_el = np.unique(frame.yarn, return_index=True)
        ids = np.searchsorted(np.unique(frame.yarn), frame.yarn)
        tot = np.bincount(ids, weights=L)
        s_loc = cum + 0.5 * L - cum[first_el[ids]]   # midpoint arc length from the yarn's first element
        tot = tot[ids]
        ds = np.abs(s_loc[a] - s_loc[b])
        ds = np.minimum(ds, tot[a] - ds)
        near = same & (ds < arc_exclusion * (rc[a] + rc[b]) + 0.5 * (L[a] + L[b]))
        a, b, qi = a[~near], b[~near], qi[~near]
    sh = shifts[qi]
    dist, _, _ = segment_distances(x0[a], d[a], x0[b] + sh, d[b])
    depth = rc[a] + rc[b] - dist
    hit = depth > tol
    a, b, qi, depth = a[hit], b[hit], qi[hit], depth[hit]
    order = np.argsort(-depth, kind="stable")
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


# ----------------------------------------------------------------------------------------
# the generator
def _lcm(values):
    out = 1
    for v in values:
        out = out * int(v) // math.gcd(out, int(v))
    return out


def _as_bar(name, spec) -> Bar:
    if isinstance(spec, Bar):
        return spec
    if not isinstance(spec, dict):
        raise InputError(f"bar {name!r}: expected a table with lapping, yarn, bed, threading; got {spec!r}")
    known = {"name", "lapping", "yarn", "bed", "threading", "system"}
    unknown = sorted(set(spec) - known)
    if unknown:
        raise InputError(f"bar {name!r}: unknown key(s) {unknown}; known: {sorted(known)}")
    for key in ("lapping", "yarn"):
        if key not in spec:
            raise InputError(f"bar {name!r}: missing key {key!r}")
    return Bar(name=spec.get("name", name), lapping=spec["lapping"], yarn=spec["yarn"],
               bed=spec.get("bed", "front"), threading=spec.get("threading", "full"),
               system=spec.get("system"))


@dataclass
class _YarnPlan:
    bar: Bar
    guide: int
    courses: list
    role: str  # "ground", "inlay", "pile"
    points: list = field(default_factory=list)     # control points (global, unwrapped)
    nseg: list = field(default_factory=list)       # elements factor per segment (number of sub-segments)


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
    elements_per_segment : beams per control segment (resolution).
    pile_segments : control segments along each pile leg between the layers.
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
    try:
        gauge = float(gauge)
        cpc = float(courses_per_cm)
        T = float(thickness)
    except (TypeError, ValueError) as exc:
        raise InputError(f"gauge, courses_per_cm and thickness must be numbers: {exc}") from None
    for nm, v in (("gauge", gauge), ("courses_per_cm", cpc), ("thickness", T)):
        if not (np.isfinite(v) and v > 0):
            raise InputError(f"{nm} must be positive and finite, got {v}")
    eps = int(elements_per_segment)
    if eps < 1 or eps != elements_per_segment:
        raise InputError(f"elements_per_segment must be an integer >= 1, got {elements_per_segment}")
    nleg = int(pile_segments)
    if nleg < 1 or nleg != pile_segments:
        raise InputError(f"pile_segments must be an integer >= 1, got {pile_segments}")
    sh = dict(SHAPE_DEFAULTS)
    if shape:
        unknown = sorted(set(shape) - set(SHAPE_DEFAULTS))
        if unknown:
            raise InputError(f"shape: unknown key(s) {unknown}; known: {sorted(SHAPE_DEFAULTS)}")
        sh.update({k: float(v) for k, v in shape.items()})
    w = INCH / gauge
    cs = 10.0 / cpc

    if isinstance(bars, dict):
        bar_list = [_as_bar(k, v) for k, v in bars.items()]
    else:
        bar_list = [_as_bar(getattr(b, "name", None) or (b.get("name") if isinstance(b, dict) else f"bar{i}"), b)
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
    C = _lcm(len(v) for v in parsed.values())
    W = _lcm(len(v) for v in threads.values())
    Lx, Ly = W * w, C * cs
    periods = np.array([[Lx, 0.0, 0.0], [0.0, Ly, 0.0]])

    def role_of(b):
        if b.bed == "both":
            return "pile"
        courses = parsed[b.name]
        pairs = [c.front if b.bed == "front" else c.back for c in courses]
        return "ground" if any(p[0] != p[1] for p in pairs) else "inlay"

    # radii per layer and role -> levels
    rmax = {}
    for b in bar_list:
        r = yarns[b.yarn].rc
        role = role_of(b)
        layers = ("front", "back") if role == "pile" else (b.bed,)
        for lay in layers:
            key = (lay, role)
            rmax[key] = max(rmax.get(key, 0.0), r)
    levels = {}
    for lay in ("front", "back"):
        levels[lay] = layer_levels(rmax.get((lay, "ground"), 0.0), rmax.get((lay, "inlay"), 0.0),
                                   rmax.get((lay, "pile"), 0.0), sh["clearance"])

    def to_global(lay, pts):
        """(x, y, depth) in a layer -> global (x, y, z)."""
        pts = np.asarray(pts, float)
        out = pts.copy()
        if lay == "front":
            out[:, 2] = T - pts[:, 2]
        else:
            out[:, 1] = pts[:, 1] + sh["back_shift"] * cs
        return out

    hl, hh, hp = sh["loop_half_width"] * w, sh["head_half_width"] * w, sh["pile_half_width"] * w

    def ground_loop(lay, needle, side, y0):
        lv = levels[lay]
        xn = (needle + 0.5) * w
        f = np.array([
            [xn + side * hl, y0 + sh["foot"] * cs, lv["foot"]],
            [xn + side * hl, y0 + sh["leg"] * cs, lv["leg"]],
            [xn + side * hh, y0 + sh["head"] * cs, lv["head"]],
            [xn - side * hh, y0 + sh["head"] * cs, lv["head"]],
            [xn - side * hl, y0 + sh["leg"] * cs, lv["leg"]],
            [xn - side * hl, y0 + sh["foot"] * cs, lv["foot"]],
        ])
        return to_global(lay, f)

    def pile_loop(lay, needle, side, y0):
        lv = levels[lay]
        xn = (needle + 0.5) * w
        y = y0 + sh["pile"] * cs
        dy = sh["pile_stagger"] * cs
        f = np.array([
            [xn + side * hp, y - dy, lv["low"]],
            [xn + side * hp, y - dy, lv["pile"]],
            [xn - side * hp, y + dy, lv["pile"]],
            [xn - side * hp, y + dy, lv["low"]],
        ])
        return to_global(lay, f)

    def inlay_point(lay, gap, y0):
        d = levels[lay]["inlay"]
        return to_global(lay, [[gap * w, y0 + sh["inlay_from"] * cs, d], [gap * w, y0 + sh["inlay_to"] * cs, d]])

    # ------------------------------------------------------------------ yarn control points
    plans = []
    for b in bar_list:
        role = role_of(b)
        thr = threads[b.name]
        courses = parsed[b.name] * (C // len(parsed[b.name]))
        for g in range(W):
            if not thr[g % len(thr)]:
                continue
            plan = _YarnPlan(bar=b, guide=g, courses=courses, role=role)
            pts, lays = [], []   # list of (points array, layer)
            for c, cl in enumerate(courses):
                y0 = c * cs
                for lay in ("front", "back"):
                    pair = getattr(cl, lay)
                    if pair is None:
                        continue
                    a, bb = pair[0] + g, pair[1] + g
                    if a == bb:
                        pts.append(inlay_point(lay, a, y0))
                    else:
                        side = 1.0 if a > bb else -1.0
                        needle = min(a, bb)
                        pts.append(pile_loop(lay, needle, side, y0) if role == "pile"
                                   else ground_loop(lay, needle, side, y0))
                    lays.append(lay)
            # assemble with straight pile legs between visits of different layers
            closing = np.array([0.0, Ly, 0.0])
            allp, nseg = [], []
            nv = len(pts)
            for v in range(nv):
                blk = pts[v]
                nxt_lay = lays[(v + 1) % nv]
                allp.append(blk)
                nseg.extend([1] * len(blk))
                if nxt_lay != lays[v]:
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

    # ------------------------------------------------------------------ discretise
    node_blocks, el_blocks, img_blocks, yarn_ids, yinfo = [], [], [], [], []
    ctrl_blocks = []     # True at the control points (the same points at every resolution)
    n0 = 0
    for yid, plan in enumerate(plans):
        nper = plan.nseg * eps
        samples = catmull_rom_periodic(plan.points, np.array([0.0, Ly, 0.0]), nper)
        wrapped, el, im = wrap_chain(samples, periods, np.array([0, 1]))
        is_ctrl = np.zeros(len(samples), dtype=bool)
        is_ctrl[np.cumsum(nper) - nper] = True
        ctrl_blocks.append(is_ctrl)
        node_blocks.append(wrapped)
        el_blocks.append(el + n0)
        img_blocks.append(im)
        yarn_ids.append(np.full(len(el), yid))
        n0 += len(wrapped)
    nodes = np.vstack(node_blocks)
    is_control = np.concatenate(ctrl_blocks)
    elements = np.vstack(el_blocks)
    images = np.vstack(img_blocks)
    yarn = np.concatenate(yarn_ids)
    ytypes = [yarns[p.bar.yarn] for p in plans]
    a_el = np.array([ytypes[y].a for y in yarn])
    b_el = np.array([ytypes[y].b for y in yarn])
    E_el = np.array([ytypes[y].E for y in yarn])
    bf_el = np.array([ytypes[y].bending_factor for y in yarn])
    tf_el = np.array([ytypes[y].torsion_factor for y in yarn])
    nu_el = np.array([ytypes[y].nu for y in yarn])
    rc_el = np.array([ytypes[y].rc for y in yarn])

    # respect the thickness exactly: affine map of z so the outer yarn surfaces sit at 0 and T
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

    # interlacing bonds: short connector beams from pile / inlay nodes inside a layer to the
    # nearest ground-loop node (frictionless contact alone cannot hold knitted loops together)
    n_yarn_el = len(elements)
    frame0 = Frame(nodes, elements, semi_axes=np.column_stack([a_el, b_el]), E=E_el, nu=nu_el, yarn=yarn,
                   periods=periods, images=images, contact_radius=rc_el,
                   ref=_reference_vectors(nodes, elements, images @ periods))
    rc_el_yarn = rc_el.copy()
    gy_el = np.array([int(np.flatnonzero(yarn == y)[0]) for y in range(len(plans))])
    bond_mask = np.zeros(0, dtype=bool)
    if bond_distance > 0:
        role_y = np.array([p.role for p in plans])
        node_yarn = np.empty(len(nodes), dtype=np.int64)
        node_yarn[elements[:, 0]] = yarn
        node_r = np.zeros(len(nodes))
        node_r[elements[:, 0]] = rc_el
        zc = 0.5 * T
        in_layer = np.abs(nodes[:, 2] - zc) > zc - levels["front"]["low"] - 1e-9
        # bonds join control points only: the interlacings of the knit, the same at every
        # resolution (bonding every node within reach made the cell stiffer with refinement)
        ground = in_layer & is_control & (role_y[node_yarn] == "ground")
        other = in_layer & is_control & (role_y[node_yarn] != "ground")
        gi, oi = np.flatnonzero(ground), np.flatnonzero(other)
        if len(gi) and len(oi):
            from scipy.spatial import cKDTree
            box = np.array([Lx, Ly, 1e6])
            tree = cKDTree(np.mod(nodes[gi], box), boxsize=box)
            dist, j = tree.query(np.mod(nodes[oi], box))
            ok = dist < bond_distance
            a_n, b_n = oi[ok], gi[j[ok]]
            if len(a_n):
                diff = nodes[b_n] - nodes[a_n]
                img = -np.round(diff[:, :2] / np.array([Lx, Ly])).astype(np.int64)
                L_b = np.linalg.norm(diff + img @ periods, axis=1)
                keep = L_b > 1e-9
                a_n, b_n, img = a_n[keep], b_n[keep], img[keep]
                gy = node_yarn[b_n]
                elements = np.vstack([elements, np.column_stack([a_n, b_n])])
                images = np.vstack([images, img])
                yarn = np.concatenate([yarn, node_yarn[b_n]])
                rb = np.minimum(a_el[gy], b_el[gy])
                a_el = np.concatenate([a_el, rb])
                b_el = np.concatenate([b_el, rb])
                E_el = np.concatenate([E_el, np.array([ytypes[y].E for y in gy])])
                bf_el = np.concatenate([bf_el, np.array([ytypes[y].bending_factor for y in gy])])
                tf_el = np.concatenate([tf_el, np.array([ytypes[y].torsion_factor for y in gy])])
                nu_el = np.concatenate([nu_el, np.array([ytypes[y].nu for y in gy])])
                rc_el = np.concatenate([rc_el, rc_el_yarn[gy_el[gy]]])
        bond_mask = np.arange(len(elements)) >= n_yarn_el
    frame = Frame(nodes, elements, semi_axes=np.column_stack([a_el, b_el]), E=E_el, nu=nu_el, yarn=yarn,
                  periods=periods, images=images, contact_radius=rc_el, bending_factor=bf_el,
                  torsion_factor=tf_el,
                  ref=_reference_vectors(nodes, elements, images @ periods))

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
    info = {
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
        "shape": sh,
        "n_bonds": int(is_bond.sum()),
    }
    if check_overlaps:
        ov = yarn_overlaps(frame0)
        info["overlaps"] = ov
        if len(ov):
            warnings.warn(f"spacer fabric: {overlap_summary(ov, yarn_group=info['yarn_group'])} at creation "
                          f"(left for the contact solver to relax)", stacklevel=2)
    return frame, info


def _reference_vectors(nodes, elements, shift):
    """Per-element reference vector: global z, or global x for elements within ~25 degrees of z."""
    d = nodes[elements[:, 1]] + shift - nodes[elements[:, 0]]
    e1 = d / np.linalg.norm(d, axis=1)[:, None]
    ref = np.zeros_like(d)
    ref[:, 2] = 1.0
    ref[np.abs(e1[:, 2]) > 0.9] = (1.0, 0.0, 0.0)
    return ref


def build_cell(parameters: dict, yarns: dict[str, YarnType], resolution: dict) -> tuple[Frame, dict]:
    """Generator entry point for cell files with ``generator = "spacer"``.

    Parameters
    ----------
    parameters : the cell's [parameters] table: gauge (needles/inch), courses_per_cm,
        thickness (mm), bars ({name: {lapping, yarn, bed, threading, system}}), optional
        shape ({key: value}, see :data:`SHAPE_DEFAULTS`); ``seam`` (a table read by
        :func:`homtex.seam_profile`, ignored here).
    yarns : yarn types by name.
    resolution : the [resolution] table: elements_per_segment (default 4), pile_segments
        (default 4).

    Returns
    -------
    (frame, info) as :func:`spacer_fabric`.
    """
    p = dict(parameters)
    known = {"gauge", "courses_per_cm", "thickness", "bars", "shape", "seam", "bond_distance"}
    unknown = sorted(set(p) - known)
    if unknown:
        raise InputError(f"[parameters]: unknown key(s) {unknown} for generator 'spacer'; known: {sorted(known)}")
    for key in ("gauge", "courses_per_cm", "thickness", "bars"):
        if key not in p:
            raise InputError(f"[parameters]: missing key {key!r} for generator 'spacer'")
    bars = {k: v for k, v in p["bars"].items()} if isinstance(p["bars"], dict) else p["bars"]
    if isinstance(bars, dict):
        for name, spec in bars.items():
            if isinstance(spec, dict) and spec.get("yarn") == (p.get("seam") or {}).get("yarn"):
                raise InputError(f"bar {name!r}: yarn {spec.get('yarn')!r} is the seam's stitch yarn")
    res = dict(resolution or {})
    unknown = sorted(set(res) - {"elements_per_segment", "pile_segments"})
    if unknown:
        raise InputError(f"[resolution]: unknown key(s) {unknown}; known: elements_per_segment, pile_segments")
    return spacer_fabric(p["gauge"], p["courses_per_cm"], p["thickness"], p["bars"], yarns,
                         elements_per_segment=res.get("elements_per_segment", 4),
                         pile_segments=res.get("pile_segments", 4), shape=p.get("shape"),
                         bond_distance=float(p.get("bond_distance", 0.0)))
