"""Weft-knitted fabrics from the needle bed: notation -> periodic cell of yarn centerlines.

Notation (:func:`parse_notation`): one string per course, one character per needle position
across the bed (front and back needles alternate position by position in rib gating):
``f`` knit on the front bed, ``b`` knit on the back bed, ``t``/``u`` tuck front/back, ``-`` or
``.`` miss. Shipped: jersey ``["f"]``, 1x1 rib ``["fb"]``, full milano ``["fb", "f-", "-b"]``
(a rib course, then a course on each bed); also interlock ``["f--b", "-bf-"]`` (two 1x1 rib
courses on alternate needles, in rib gating) and tuck patterns (``["ff", "ft"]``). Every course
runs in +x (a circular machine's spiral, cut into one yarn per course closing over the cell's
width); the cell repeats the pattern: a1 = (positions x pitch, 0,
0) along the courses, a2 = (0, courses x course spacing, 0) along the wales.

Loop geometry (stated model): each knitted loop follows the plain-knit curve of K. Crane, "A
simple parametric model of plain-knit yarns" (https://www.cs.cmu.edu/~kmcrane/Projects/Other/YarnCurve.pdf,
code at https://github.com/keenancrane/plain-knit-yarn: gamma(t) = (t + a sin 2t, h cos t,
d cos 2t)), here with z mirrored so that the technical face looks towards +z, per needle position
with t in [-pi, pi):

    x = x_c + lambda (t + a sin 2t),   y = y_c + H_m + H_a cos t,   z = sigma(t) (Z0 - d cos 2t),

lambda = pitch / (2 pi), a = 3/2 (loop roundness), head at t = 0; in Crane's units (lambda = 1)
h = 4, d = 1, course spacing h + 1/2 and a snug tube radius 4/5 (one loop is then 24.67 long:
30.8 snug radii). A loop held on its needle for m courses (milano) reaches m - 1 course spacings
higher: its bottom stays at y_c - h (where it passes through the loop below), its head at
y_c + h + (m - 1) c. A missed needle carries a float at the sinker level, x = x_c + lambda t (it
runs straight across: the loop's lateral bulge a sin 2t would fold it back on itself), bulging by d
towards its bed. A tuck leaves the needle's old loop on it (held until the needle next knits)
and lays a loop beside it that is not knitted through: from the sinker level of its course up to
the held loop's head, x as a knit loop's, z the knit loop's depth profile moved back by up to
TUCK_DEPTH d = 1.5 d at its head (s (Z0 - d cos 2t - 1.5 d (1 + cos t) / 2)). It then lies behind
the held loop all the way (the two are not interlooped), with its legs in front of the next
loop's feet and its head behind that loop's legs, so the next loop passes through both, as on the
machine's hook; 1.5 keeps different courses furthest apart (clear radius 0.055 mm for a 6.5 mm
loop of ["ff", "ft"], against 0.025 mm at 1 d and 0.045 mm at 2 d). A stated geometry, not checked
against measured tuck fabrics: relaxed, the E-glass ["ff", "ft"] widens (wale spacing 2.07 mm
against 1.87 mm for jersey) and shortens (course spacing 0.83 mm against 1.88 mm), as tuck
fabrics do. sigma is +1 on the front bed (technical face towards +z: legs outside, head and sinkers inside)
and -1 on the back bed (a back loop is the front loop mirrored), blended smoothly to 0 where the
yarn crosses between the beds; the bed offset Z0 is 0 for one bed and, for two, the one of
:data:`BEDS` that keeps different courses furthest apart. The curve is analytic per position and
continuous in position and tangent. The whole geometry scales with the
loop (stitch) length: by default every length is Crane's times loop_length / 24.67 (per stitch of
the pattern); given the wale and course spacing, only the depth d is solved for the loop length.
A loop whose yarn cannot close around its neighbours (the cell's clear radius, half the smallest
distance between different courses, below the yarn's incompressible radius; or a loop length shorter
than the flat curve) is refused with its course and needle named; overlaps of the yarn surfaces at
creation are reported (compressible yarns overlap on purpose: their shells flatten in the
relaxation).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import CellError

__all__ = ["CRANE", "KnitPattern", "course_curve", "knit_geometry", "parse_notation", "stitch_length"]

#: Crane's plain-knit curve in its own units (lambda = 1): roundness a, loop half-height h, depth d,
#: course spacing c, snug tube radius, length of one loop
CRANE = {"a": 1.5, "h": 4.0, "d": 1.0, "c": 4.5, "snug": 0.8}

#: bed offsets Z0 / d tried for two-bed fabrics (front loops' heads and sinkers between the beds, their
#: legs outside); the one that keeps different courses furthest apart is taken (a 1x1 rib: 0.5, its
#: clear radius 0.69 snug radii; full milano: 1.0)
BEDS = (0.25, 0.5, 0.75, 1.0, 1.25)

#: how far behind the knit loop's depth profile a tuck loop runs at its head (x d)
TUCK_DEPTH = 1.5

SYMBOLS = {"f": ("knit", 1), "b": ("knit", -1), "t": ("tuck", 1), "u": ("tuck", -1), "-": ("miss", 0),
           ".": ("miss", 0)}


@dataclass
class KnitPattern:
    """A parsed notation: ``action`` (C, N) str ('knit', 'miss'), ``bed`` (C, N) int (+1 front,
    -1 back, 0 miss) for C courses over N needle positions."""

    courses: list
    action: np.ndarray
    bed: np.ndarray

    @property
    def n_courses(self) -> int:
        return self.action.shape[0]

    @property
    def n_needles(self) -> int:
        return self.action.shape[1]

    def held(self) -> np.ndarray:
        """(C, N) courses each knitted loop stays on its needle (1: knitted through next course)."""
        C, N = self.action.shape
        m = np.zeros((C, N), dtype=np.int64)
        for i in range(N):
            knit = np.flatnonzero(self.action[:, i] == "knit")
            for q, j in enumerate(knit):
                nxt = knit[(q + 1) % len(knit)] + (C if q + 1 == len(knit) else 0)
                m[j, i] = nxt - j
        return m

    def next_knit(self, j: int, i: int) -> int:
        """The course (counted on past the pattern's end) that next knits needle i after course j."""
        C = self.action.shape[0]
        return next(q for q in range(j + 1, j + C + 1) if self.action[q % C, i] == "knit")

    def stitches(self) -> int:
        return int(np.count_nonzero(self.action == "knit"))


def parse_notation(courses, needles: int | None = None, table: str = "parameters") -> KnitPattern:
    """Check a notation (see the module docstring) and return its :class:`KnitPattern`.

    ``needles``: the bed's width in needle positions (default: the courses' width). CellError names
    the course and needle of: an unknown symbol, a stitch outside the bed, a course that knits no
    needle, a needle that never knits, a needle position on both beds.
    """
    if isinstance(courses, str) or not isinstance(courses, (list, tuple)) or not courses:
        raise CellError("must be a non-empty array of strings, one per course (e.g. [\"fb\"] for a 1x1 rib)",
                        table=table, key="notation")
    width = needles if needles is not None else max(len(c) if isinstance(c, str) else 0 for c in courses)
    act = np.full((len(courses), width), "miss", dtype=object)
    bed = np.zeros((len(courses), width), dtype=np.int64)
    for j, course in enumerate(courses):
        if not isinstance(course, str):
            raise CellError(f"course {j + 1} must be a string of needle symbols, got {course!r}", table=table,
                            key="notation")
        if len(course) > width:
            raise CellError(f"course {j + 1}, needle {width + 1}: stitch outside the bed (the bed has {width} "
                            "needle positions)", table=table, key="notation")
        if len(course) < width:
            raise CellError(f"course {j + 1} has {len(course)} needle positions, the others {width}: give every "
                            "needle a symbol ('-' for a miss)", table=table, key="notation")
        for i, ch in enumerate(course):
            if ch not in SYMBOLS:
                raise CellError(f"course {j + 1}, needle {i + 1}: unknown symbol {ch!r} (f/b knit front/back, t/u "
                                "tuck front/back, - or . miss)", table=table, key="notation")
            a, s = SYMBOLS[ch]
            act[j, i], bed[j, i] = a, s
        if not np.any(act[j] == "knit"):
            raise CellError(f"course {j + 1} knits no needle ({course!r})", table=table, key="notation")
    for i in range(width):
        if not np.any(act[:, i] == "knit"):
            raise CellError(f"needle {i + 1} never knits: no course holds a loop there (course 1 of "
                            f"{len(courses)})", table=table, key="notation")
        beds = set(bed[act[:, i] != "miss", i].tolist())
        if len(beds) > 1:
            j = int(np.flatnonzero(act[:, i] != "miss")[1])
            raise CellError(f"course {j + 1}, needle {i + 1}: a needle position knits on both beds (front and back "
                            "needles have positions of their own in rib gating)", table=table, key="notation")
    return KnitPattern(courses=list(courses), action=act, bed=bed)


# ---------------------------------------------------------------------------------------------
def _sigma(t, s_left, s_mid, s_right):
    """Bed sign along a position: s_mid at its centre, blended to the boundary values s_left
    (t = -pi) and s_right (t = pi) with zero slope at both ends."""
    w = ((1.0 - np.cos(t)) / 2.0) ** 2
    return np.where(t < 0, s_mid + (s_left - s_mid) * w, s_mid + (s_right - s_mid) * w)


def course_curve(pat: KnitPattern, j: int, *, pitch: float, c: float, h: float, d: float, Z0: float,
                 a: float = CRANE["a"], samples: int = 256) -> np.ndarray:
    """Dense centerline (N samples, 3) of course j over one cell width (the curve continues with
    the first point shifted by (N pitch, 0, 0)), mm. h, d: loop half-height and depth; c: course
    spacing; Z0: bed offset."""
    N = pat.n_needles
    held = pat.held()
    lam = pitch / (2.0 * np.pi)
    t = -np.pi + 2.0 * np.pi * np.arange(samples) / samples
    beds = pat.bed[j]
    knit = pat.action[j] == "knit"
    tuck = pat.action[j] == "tuck"
    onbed = knit | tuck
    # each position's bed sign; floats take their neighbours' on a bed (one bed) or 0 (between)
    sig = beds.astype(float)
    for i in np.flatnonzero(~onbed):
        lft = next(beds[(i - q) % N] for q in range(1, N + 1) if onbed[(i - q) % N])
        rgt = next(beds[(i + q) % N] for q in range(1, N + 1) if onbed[(i + q) % N])
        sig[i] = 0.5 * (lft + rgt)
    out = []
    y0 = j * c
    for i in range(N):
        sl = 0.5 * (sig[i] + sig[(i - 1) % N])
        sr = 0.5 * (sig[i] + sig[(i + 1) % N])
        s = _sigma(t, sl, sig[i], sr)
        xc = (i + 0.5) * pitch
        if knit[i]:
            m = held[j, i]
            Hm, Ha = 0.5 * (m - 1) * c, h + 0.5 * (m - 1) * c
            x = xc + lam * (t + a * np.sin(2.0 * t))
            y = y0 + Hm + Ha * np.cos(t)
            z = s * (Z0 - d * np.cos(2.0 * t))
        elif tuck[i]:
            # from the sinker level up to the head of the loop held on the needle, the knit loop's
            # depth profile moved back by up to d: behind the held loop all the way (not through
            # it), legs in front of the next loop's feet and head behind its legs (caught by it)
            top = (pat.next_knit(j, i) - 1) * c + h
            x = xc + lam * (t + a * np.sin(2.0 * t))
            y = y0 - h + (top - y0 + h) * (1.0 + np.cos(t)) / 2.0
            z = s * (Z0 - d * np.cos(2.0 * t) - TUCK_DEPTH * d * (1.0 + np.cos(t)) / 2.0)
        else:
            x = xc + lam * t                                   # straight across (no loop to turn round)
            y = np.full_like(t, y0 - h)
            z = s * (Z0 - d + d * (1.0 + np.cos(t)) / 2.0)      # bulges by d towards its bed
        out.append(np.column_stack([x, y, z]))
    return np.vstack(out)


def _length(curve: np.ndarray, period: float) -> float:
    d = np.diff(np.vstack([curve, curve[:1] + [period, 0.0, 0.0]]), axis=0)
    return float(np.linalg.norm(d, axis=1).sum())


def stitch_length(pat: KnitPattern, **geo) -> float:
    """Mean yarn length per stitch (course length / stitches knitted in it, over the pattern), mm."""
    period = pat.n_needles * geo["pitch"]
    total = sum(_length(course_curve(pat, j, **geo), period) for j in range(pat.n_courses))
    return total / pat.stitches()


def clear_radius(pat: KnitPattern, samples: int = 48, where: bool = False, **geo):
    """Half the smallest centreline distance between different courses of the pattern (periodic
    images included), mm: the largest solid yarn radius the generated cell holds without overlaps.
    ``where``: also return the (course, needle) (0-based) of the tightest spot."""
    from scipy.spatial import cKDTree

    P, H = pat.n_needles * geo["pitch"], pat.n_courses * geo["c"]
    base = [course_curve(pat, j, samples=samples, **geo) for j in range(pat.n_courses)]
    trees = [cKDTree(b) for b in base]
    best, spot = np.inf, (0, 0)
    for j, cj in enumerate(base):
        for q in range(-1, 2):
            for k in range(-1, 2):
                for i in range(pat.n_courses):
                    if (q, k) == (0, 0) and i <= j:
                        continue
                    if q == 0 and i == j:
                        continue
                    dist, _ = trees[i].query(cj + [k * P, q * H, 0.0])
                    e = int(np.argmin(dist))
                    if dist[e] < best:
                        best, spot = float(dist[e]), (j, e // samples)
    return (0.5 * best, spot) if where else 0.5 * best


def knit_geometry(pat: KnitPattern, loop_length: float, *, core_radius: float, wale_spacing: float | None = None,
                  course_spacing: float | None = None, table: str = "parameters") -> dict:
    """The geometry parameters (pitch, c, h, d, Z0, a: mm) of the stated loop model for a stitch
    length ``loop_length`` (mm); see the module docstring. ``core_radius``: the yarn's
    incompressible radius (mm), below which a loop cannot close. ``wale_spacing`` (mm, between
    wales of one bed) and ``course_spacing`` (mm) fix the x and y scales; only the depth is solved."""
    two_beds = bool(np.any(pat.bed < 0)) and bool(np.any(pat.bed > 0))
    knit = np.argwhere(pat.action == "knit")[0]
    where = f"course {knit[0] + 1}, needle {knit[1] + 1}"
    per_wale = 2 if two_beds else 1
    beds = 0.0
    if two_beds:
        unit = dict(pitch=2 * np.pi, c=CRANE["c"], h=CRANE["h"], d=CRANE["d"])
        beds = max(BEDS, key=lambda b: clear_radius(pat, **unit, Z0=b * CRANE["d"]))
    if wale_spacing is None and course_spacing is None:
        unit = dict(pitch=2 * np.pi, c=CRANE["c"], h=CRANE["h"], d=CRANE["d"], Z0=beds * CRANE["d"])
        s = loop_length / stitch_length(pat, **unit)
        geo = {k: v * s for k, v in unit.items()}
    else:
        if wale_spacing is None or course_spacing is None:
            raise CellError("give both wale_spacing and course_spacing (or neither: the loop length sets both)",
                            table=table, key="wale_spacing" if wale_spacing is None else "course_spacing")
        pitch = wale_spacing / per_wale
        lam = pitch / (2 * np.pi)
        c = course_spacing
        geo = dict(pitch=pitch, c=c, h=c * CRANE["h"] / CRANE["c"], d=0.0, Z0=0.0)

        def length(dd):
            return stitch_length(pat, **{**geo, "d": dd, "Z0": beds * dd})
        flat = length(1e-9 * lam)
        if flat > loop_length:
            raise CellError(f"{where}: a loop too short to close: loop length {loop_length:g} mm, but the loop model "
                            f"needs {flat:.4g} mm at wale spacing {wale_spacing:g} mm and course spacing "
                            f"{course_spacing:g} mm even flat", table=table, key="loop_length")
        lo, hi = 0.0, lam
        while length(hi) < loop_length:
            hi *= 2.0
            if hi > 1e3 * lam:
                raise CellError(f"{where}: loop length {loop_length:g} mm is far longer than the wale and course "
                                "spacing allow", table=table, key="loop_length")
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if length(mid) < loop_length else (lo, mid)
        geo.update(d=0.5 * (lo + hi), Z0=beds * 0.5 * (lo + hi))
    snug, (jt, it) = clear_radius(pat, where=True, **{k: geo[k] for k in ("pitch", "c", "h", "d", "Z0")})
    if core_radius > snug * (1.0 + 1e-9) and snug <= 0.0:
        raise CellError(f"course {jt + 1}, needle {it + 1}: a loop too short to close: loop length {loop_length:g} mm "
                        "gives loops that clear no yarn at all", table=table, key="loop_length")
    if core_radius > snug * (1.0 + 1e-9):
        raise CellError(f"course {jt + 1}, needle {it + 1}: a loop too short to close: loop length {loop_length:g} mm "
                        "gives loops that clear "
                        f"a yarn of radius {snug:.4g} mm, but the yarn's incompressible radius is "
                        f"{core_radius:.4g} mm (loop length at least {loop_length * core_radius / snug:.4g} mm)",
                        table=table, key="loop_length")
    geo["a"] = CRANE["a"]
    geo["clear_radius"] = snug
    geo["wale_spacing"] = geo["pitch"] * per_wale
    return geo


# ---------------------------------------------------------------------------------------------
def resample(curve: np.ndarray, period: float, n: int) -> np.ndarray:
    """n points at equal arc length along a closed-by-translation curve (its first point kept)."""
    pts = np.vstack([curve, curve[:1] + [period, 0.0, 0.0]])
    s = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))]
    u = np.arange(n) * s[-1] / n
    return np.column_stack([np.interp(u, s, pts[:, k]) for k in range(3)])


def hex_offsets(n: int, spacing: float) -> np.ndarray:
    """(n, 2) positions of n filaments packed hexagonally around the yarn's axis (mm): rings of
    6, 12, ... around a centre filament, each ring filled nearest first."""
    pts = [(0.0, 0.0)]
    ring = 1
    while len(pts) < n:
        cand = []
        for q in range(6):
            a0, a1 = np.pi / 3 * q, np.pi / 3 * (q + 1)
            p0 = ring * np.array([np.cos(a0), np.sin(a0)])
            p1 = ring * np.array([np.cos(a1), np.sin(a1)])
            for k in range(ring):
                cand.append(p0 + (p1 - p0) * k / ring)
        cand.sort(key=lambda p: (round(float(np.hypot(*p)), 9), float(np.arctan2(p[1], p[0]))))
        pts.extend(tuple(p) for p in cand[:n - len(pts)])
        ring += 1
    return spacing * np.array(pts[:n])
