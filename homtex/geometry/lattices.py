"""Strut lattices: unit cells, periodic cells, supercells and finite blocks.

A :class:`LatticeCell` holds lattice vectors, the points of one cell and the
struts between them (strut s joins point a to point b shifted by
``images[s] @ basis``). :func:`lattice_frame` turns it into a beam
:class:`~homtex.Frame`: periodic (with image offsets) or a finite block of
``repeat`` cells, each strut split into ``elements_per_strut`` beams.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from ..errors import CellError, InputError
from ..model.arrays import as_index
from ..model.frame import Frame
from ..validate import check_int, check_keys, check_size, get_int, get_list, get_number, get_str


@dataclass
class LatticeCell:
    """One periodic cell of a strut lattice (lengths in mm).

    basis : (k, 3) lattice vectors; points : (p, 3); struts : (s, 2) point
    indices; images : (s, k) integer offsets of each strut's second point.
    """

    name: str
    basis: np.ndarray
    points: np.ndarray
    struts: np.ndarray
    images: np.ndarray


def neighbor_struts(basis, points, cutoff, rtol=1e-6):
    """All point pairs (a, b + image) closer than ``cutoff`` (each strut once)."""
    basis = np.asarray(basis, float)
    k = len(basis)
    pts = np.asarray(points, float)
    struts, imgs = [], []
    for img in itertools.product((-1, 0, 1), repeat=k):
        img = np.array(img)
        d = pts[None, :, :] + img @ basis - pts[:, None, :]
        dist = np.linalg.norm(d, axis=2)
        a, b = np.nonzero((dist < cutoff * (1 + rtol)) & (dist > 1e-12))
        for ai, bi in zip(a, b):
            # keep one direction: (a < b) or (a == b and first non-zero image > 0)
            if ai < bi or (ai == bi and img[np.flatnonzero(img)[0]] > 0):
                struts.append((ai, bi))
                imgs.append(img)
    if not struts:
        raise InputError(f"no two lattice points are closer than the cutoff {cutoff:g} mm: the lattice has no "
                         "struts (a lattice constant of 0 or beyond double precision?)")
    return np.array(struts, dtype=np.int64), np.array(imgs, dtype=np.int64).reshape(-1, k)


def simple_cubic(a: float = 1.0) -> LatticeCell:
    """Simple cubic lattice of edge ``a``: one point, three struts."""
    basis = a * np.eye(3)
    return LatticeCell("simple_cubic", basis, np.zeros((1, 3)),
                       np.zeros((3, 2), dtype=np.int64), np.eye(3, dtype=np.int64))


def bcc(a: float = 1.0) -> LatticeCell:
    """Body-centred cubic strut lattice: centre joined to the 8 corners."""
    basis = a * np.eye(3)
    pts = np.array([[0, 0, 0], [0.5, 0.5, 0.5]]) * a
    s, im = neighbor_struts(basis, pts, np.sqrt(3) / 2 * a)
    return LatticeCell("bcc", basis, pts, s, im)


def octet(a: float = 1.0) -> LatticeCell:
    """Octet truss: FCC points, each joined to its 12 nearest neighbours."""
    basis = a * np.eye(3)
    pts = np.array([[0, 0, 0], [0.5, 0.5, 0], [0.5, 0, 0.5], [0, 0.5, 0.5]]) * a
    s, im = neighbor_struts(basis, pts, a / np.sqrt(2))
    return LatticeCell("octet", basis, pts, s, im)


def square(a: float = 1.0) -> LatticeCell:
    """Square lattice in the x-y plane."""
    return LatticeCell("square", a * np.eye(3)[:2], np.zeros((1, 3)),
                       np.zeros((2, 2), dtype=np.int64), np.eye(2, dtype=np.int64))


def triangular(a: float = 1.0) -> LatticeCell:
    """Triangular lattice in the x-y plane (struts of length a)."""
    basis = a * np.array([[1.0, 0, 0], [0.5, np.sqrt(3) / 2, 0]])
    s = np.zeros((3, 2), dtype=np.int64)
    return LatticeCell("triangular", basis, np.zeros((1, 3)), s,
                       np.array([[1, 0], [0, 1], [-1, 1]], dtype=np.int64))


def honeycomb(h: float = 1.0, l: float = 1.0, theta: float = 30.0) -> LatticeCell:
    """Hexagonal honeycomb in the x-y plane (Gibson-Ashby / Masters-Evans geometry).

    Vertical walls of length ``h`` along y, inclined walls of length ``l`` at
    angle ``theta`` (degrees) to the x axis; theta < 0 gives the re-entrant
    (auxetic) honeycomb. The regular honeycomb is h = l, theta = 30.
    """
    t = np.radians(theta)
    if not (-90 < theta < 90) or theta == 0.0:
        raise InputError(f"honeycomb: theta must be in (-90, 90) degrees and non-zero, got {theta}")
    if h <= 0 or l <= 0:
        raise InputError(f"honeycomb: wall lengths must be positive, got h={h}, l={l}")
    if h + l * np.sin(t) <= 0:
        raise InputError(f"honeycomb: h + l sin(theta) must be positive (cells would invert), "
                         f"got h={h}, l={l}, theta={theta}")
    c, s = l * np.cos(t), l * np.sin(t)
    # point 0 at the bottom of a vertical wall, point 1 at its top
    pts = np.array([[0.0, 0.0, 0.0], [0.0, h, 0.0]])
    basis = np.array([[2 * c, 0.0, 0.0], [c, h + s, 0.0]])
    struts = np.array([[0, 1], [1, 0], [1, 0]], dtype=np.int64)
    # top of wall (0, h) to bottom of the walls at (+-c, h + s): images (0,1) and (-1,1)
    images = np.array([[0, 0], [0, 1], [-1, 1]], dtype=np.int64)
    return LatticeCell(f"honeycomb(h={h}, l={l}, theta={theta})", basis, pts, struts, images)


GENERATORS = {"simple_cubic": simple_cubic, "bcc": bcc, "octet": octet,
              "square": square, "triangular": triangular, "honeycomb": honeycomb}


def _subdivide(x0, x1, a, b, img, nel, n_base, waviness=0.0, normal=None):
    """Split struts into nel elements: new interior nodes and the element list.

    With ``waviness`` w != 0 the interior nodes lie on the half-sine arc
    x(t) = x0 + t (x1 - x0) + w L sin(pi t) n (L the strut length, n the unit
    ``normal`` (s, 3) of each strut), so the strut is curved and the straight beams
    are chords of it.
    """
    s = len(a)
    if nel == 1:
        return np.zeros((0, 3)), np.column_stack([a, b]), img
    t = np.arange(1, nel) / nel
    interior = x0[:, None, :] + t[None, :, None] * (x1 - x0)[:, None, :]
    if waviness:
        L = np.linalg.norm(x1 - x0, axis=1)
        interior += (waviness * L)[:, None, None] * np.sin(np.pi * t)[None, :, None] * normal[:, None, :]
    ids = n_base + np.arange(s * (nel - 1)).reshape(s, nel - 1)
    chain = np.concatenate([a[:, None], ids, b[:, None]], axis=1)
    el = np.stack([chain[:, :-1], chain[:, 1:]], axis=2).reshape(-1, 2)
    im = np.zeros((s, nel, img.shape[1]), dtype=np.int64)
    im[:, -1] = img
    return interior.reshape(-1, 3), el, im.reshape(-1, img.shape[1])


def strut_normals(d: np.ndarray) -> np.ndarray:
    """(s, 3) unit normals of strut directions d (s, 3): z x e1 (in the x-y plane for planar
    struts), or x x e1 for struts within ~25 degrees of z."""
    e1 = d / np.linalg.norm(d, axis=1)[:, None]
    ref = np.zeros_like(e1)
    ref[:, 2] = 1.0
    ref[np.abs(e1[:, 2]) > 0.9] = (1.0, 0.0, 0.0)
    n = np.cross(ref, e1)
    return n / np.linalg.norm(n, axis=1)[:, None]


def lattice_frame(cell: LatticeCell | str, *, radius=None, E=1.0, nu=0.3, semi_axes=None,
                  elements_per_strut: int = 1, repeat=None, periodic: bool = True,
                  waviness: float = 0.0, contact_radius=None, bending_factor=None, torsion_factor=None,
                  strain_limit=None, **cell_args) -> Frame:
    """A beam frame of a lattice.

    Parameters
    ----------
    cell : LatticeCell or generator name ("simple_cubic", "bcc", "octet",
        "square", "triangular", "honeycomb"); ``cell_args`` go to the generator.
    radius, E, nu, semi_axes : section and material (see :class:`~homtex.Frame`).
    elements_per_strut : beams per strut (resolution).
    repeat : cells per lattice direction (default 1 each).
    periodic : True: a periodic frame of the repeated cell (supercell);
        False: a finite block, struts that leave the block dropped.
    waviness : amplitude of a half-sine bow of every strut, as a fraction of its length
        (0: straight struts). The bow lies along :func:`strut_normals` (in the x-y plane
        for planar lattices); the beams are chords of the curved strut, so a wavy
        lattice converges with ``elements_per_strut`` (a straight one is exact at 1).
    contact_radius : contact radius of the struts, mm (default: the section radius).
    bending_factor, torsion_factor : bending / torsional rigidity relative to the solid section
        (default 1, :class:`homtex.Frame`).
    strain_limit : elastic limit of axial/shear strain (default 0.02, :class:`homtex.Frame`).
    """
    if isinstance(cell, str):
        if cell not in GENERATORS:
            raise InputError(f"unknown lattice {cell!r}; choose from {sorted(GENERATORS)}")
        cell = GENERATORS[cell](**cell_args)
    nel = check_int(elements_per_strut, "elements_per_strut", ge=1)
    k = len(cell.basis)
    reps = np.ones(k, dtype=np.int64) if repeat is None else as_index(repeat, "repeat", lo=1)
    if reps.shape != (k,):
        raise InputError(f"repeat must hold {k} integers (one per lattice vector), got {np.shape(repeat)}")
    n_cells = 1
    for r in reps.tolist():
        n_cells *= int(r)
    check_size(n_cells * len(cell.struts) * nel, f"a {cell.name} lattice of {reps.tolist()} cells")
    p = len(cell.points)
    cells = np.array(list(itertools.product(*[range(r) for r in reps])), dtype=np.int64).reshape(-1, k)
    strides = np.cumprod(np.concatenate([[1], reps[::-1][:-1]]))[::-1]  # row-major like product
    nodes = (cells @ cell.basis)[:, None, :] + cell.points[None]
    nodes = nodes.reshape(-1, 3)
    c = np.repeat(cells, len(cell.struts), axis=0)
    sa = np.tile(cell.struts[:, 0], len(cells))
    sb = np.tile(cell.struts[:, 1], len(cells))
    simg = np.tile(cell.images, (len(cells), 1))
    target = c + simg
    if periodic:
        img = np.floor_divide(target, reps)
        target = target - img * reps
        keep = np.ones(len(c), dtype=bool)
    else:
        keep = np.all((target >= 0) & (target < reps), axis=1)
        img = np.zeros_like(target)
    a = (c @ strides) * p + sa
    b = (target @ strides) * p + sb
    a, b, img = a[keep], b[keep], img[keep]
    x0 = nodes[a]
    x1 = nodes[b] + img @ (cell.basis * reps[:, None])
    waviness = float(waviness)
    if not np.isfinite(waviness):
        raise InputError(f"waviness must be finite, got {waviness}")
    normal = strut_normals(x1 - x0) if waviness else None
    inner, el, im = _subdivide(x0, x1, a, b, img, nel, len(nodes), waviness, normal)
    allnodes = np.vstack([nodes, inner])
    kw = dict(radius=radius, E=E, nu=nu, semi_axes=semi_axes, contact_radius=contact_radius,
              bending_factor=bending_factor, torsion_factor=torsion_factor, strain_limit=strain_limit)
    if periodic:
        return Frame(allnodes, el, periods=cell.basis * reps[:, None], images=im, **kw)
    return Frame(allnodes, el, **kw)


# ----------------------------------------------------------------------------------
# cell-file builders (see homtex.cells): build(parameters, yarns, resolution) -> (Frame, info)
_COMMON = ("repeat", "yarn", "waviness")
#: largest lattice constant a cell file may give, mm
MAX_LATTICE = 1e6


def _pick_yarn(parameters, yarns, table="parameters"):

    if "yarn" in parameters:
        name = get_str(parameters, "yarn", table)
        if name not in yarns:
            raise CellError(f"no yarn type {name!r}; the file defines {sorted(yarns)}",
                            table=table, key="yarn")
        return yarns[name]
    if len(yarns) != 1:
        raise CellError(f"the file defines yarns {sorted(yarns)}: name the one the struts use",
                        table=table, key="yarn")
    return next(iter(yarns.values()))


def _build(cell: LatticeCell, parameters, yarns, resolution, table="parameters"):

    y = _pick_yarn(parameters, yarns, table)
    check_keys(resolution, ("elements_per_strut",), "resolution")
    nel = get_int(resolution, "elements_per_strut", "resolution", default=1, ge=1)
    k = len(cell.basis)
    repeat = get_list(parameters, "repeat", table, shape=(k,), integer=True, default=np.ones(k, int))
    if np.any(repeat < 1):
        raise CellError(f"entries must be >= 1, got {repeat.tolist()}", table=table, key="repeat")
    wav = get_number(parameters, "waviness", table, default=0.0, ge=-0.5, le=0.5)
    sec = dict(semi_axes=(y.a, y.b)) if y.semi_axes else dict(radius=y.radius)
    frame = lattice_frame(cell, E=y.E, nu=y.nu, contact_radius=y.rc, bending_factor=y.bending_factor,
                          torsion_factor=y.torsion_factor, strain_limit=y.strain_limit, elements_per_strut=nel,
                          repeat=repeat, waviness=wav, **sec)
    info = {"lattice": cell.name, "groups": {"struts": np.ones(frame.n_elements, dtype=bool)}}
    return frame, info


def build_honeycomb(parameters: dict, yarns: dict, resolution: dict):
    """Hexagonal honeycomb (regular or re-entrant) from a cell file.

    [parameters]: h, l (mm, > 0), theta (degrees, in (-90, 90), non-zero; < 0 re-entrant),
    optional repeat = [nx, ny], yarn, waviness. [resolution]: elements_per_strut.
    """

    t = "parameters"
    check_keys(parameters, ("h", "l", "theta", *_COMMON), t)
    h = get_number(parameters, "h", t, gt=0, le=MAX_LATTICE)
    l_ = get_number(parameters, "l", t, gt=0, le=MAX_LATTICE)
    theta = get_number(parameters, "theta", t, gt=-90, lt=90)
    if theta == 0:
        raise CellError("must be non-zero (theta = 0 collapses the cell: the lattice vectors are "
                        "not independent)", table=t, key="theta")
    if h + l_ * np.sin(np.radians(theta)) <= 1e-9 * max(h, l_):
        raise CellError(f"h + l sin(theta) = {h + l_ * np.sin(np.radians(theta)):g} must be > 0 "
                        f"(otherwise the lattice vectors are not independent)", table=t, key="theta")
    return _build(honeycomb(h, l_, theta), parameters, yarns, resolution)


def _spacing_builder(gen, doc):
    def build(parameters: dict, yarns: dict, resolution: dict):

        check_keys(parameters, ("a", *_COMMON), "parameters")
        a = get_number(parameters, "a", "parameters", gt=0, le=MAX_LATTICE)
        return _build(gen(a), parameters, yarns, resolution)
    build.__doc__ = (f"{doc} from a cell file. [parameters]: a (strut spacing, mm), optional "
                     f"repeat, yarn, waviness. [resolution]: elements_per_strut.")
    build.__name__ = f"build_{gen.__name__}"
    return build


build_square = _spacing_builder(square, "Square lattice")
build_triangular = _spacing_builder(triangular, "Triangular lattice")
build_simple_cubic = _spacing_builder(simple_cubic, "Simple cubic lattice")
build_bcc = _spacing_builder(bcc, "BCC lattice")
build_octet = _spacing_builder(octet, "Octet truss")


def build_lattice(parameters: dict, yarns: dict, resolution: dict):
    """An explicit strut lattice from a cell file.

    [parameters]: basis (k x 3 lattice vectors, mm), points (p x 3, mm), struts (s x 2 point
    indices), images (s x k integer offsets of each strut's second point), optional repeat,
    yarn, waviness. [resolution]: elements_per_strut.
    """

    t = "parameters"
    check_keys(parameters, ("basis", "points", "struts", "images", *_COMMON), t)
    basis = get_list(parameters, "basis", t, shape=(None, 3))
    k = len(basis)
    if not 1 <= k <= 3:
        raise CellError(f"must hold 1 to 3 lattice vectors, got {k}", table=t, key="basis")
    if np.linalg.matrix_rank(basis, tol=1e-9 * max(1.0, np.abs(basis).max())) < k:
        raise CellError(f"the lattice vectors {basis.tolist()} are not linearly independent",
                        table=t, key="basis")
    points = get_list(parameters, "points", t, shape=(None, 3))
    struts = get_list(parameters, "struts", t, shape=(None, 2), integer=True)
    images = get_list(parameters, "images", t, shape=(len(struts), k), integer=True)
    if len(points) == 0 or len(struts) == 0:
        raise CellError("a lattice needs at least one point and one strut", table=t,
                        key="points" if len(points) == 0 else "struts")
    bad = (struts < 0) | (struts >= len(points))
    if bad.any():
        s = int(np.flatnonzero(bad.any(axis=1))[0])
        raise CellError(f"strut {s} refers to point {struts[s].tolist()}, outside 0..{len(points) - 1}",
                        table=t, key="struts")
    return _build(LatticeCell("lattice", basis, points, struts, images), parameters, yarns, resolution)
