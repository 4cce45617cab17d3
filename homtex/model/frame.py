"""The beam frame: nodes, elements and per-element section/material data.

A :class:`Frame` is a struct of arrays. Elements join node ``i`` to node ``j``
shifted by ``images[e] @ periods`` (periodic frames); for a non-periodic frame
``periods`` has shape (0, 3) and every shift is zero.
"""

from __future__ import annotations

from functools import cached_property

import numpy as np

from ..errors import InputError
from .arrays import MAX_COORD, as_index, as_real, per_element, to_array
from .sections import DEFAULT_STRAIN_LIMIT, section_properties

#: per-element constructor arguments of a Frame, in the order :meth:`Frame.element_fields` returns them
ELEMENT_FIELDS = ("semi_axes", "E", "nu", "yarn", "ref", "contact_radius", "prestrain", "bending_factor",
                  "torsion_factor", "strain_limit")
#: defaults of the fields that have one (used when frames are joined, :func:`stack_fields`)
FIELD_DEFAULTS = {"prestrain": 0.0, "bending_factor": 1.0, "torsion_factor": 1.0,
                  "strain_limit": DEFAULT_STRAIN_LIMIT}
#: largest Young's modulus accepted, MPa (diamond is 1.2e6; beyond this only an input error)
MAX_MODULUS = 1e8
#: smallest radius accepted, mm (below it r^4 underflows)
MIN_RADIUS = 1e-9
#: largest bending / torsion factor accepted (relative to the solid section)
MAX_FACTOR = 1e6


def _first_bad(mask):
    return int(np.flatnonzero(mask)[0])


class Frame:
    """A 3D frame of two-node beams.

    Parameters
    ----------
    nodes : array (n, 3)
        Node coordinates, mm.
    elements : int array (m, 2)
        Node indices of each element.
    radius : float or array (m,)
        Circular section radius, mm. Give ``semi_axes`` instead for ellipses.
    E : float or array (m,)
        Young's modulus, MPa.
    nu : float or array (m,)
        Poisson's ratio, in (-1, 0.5).
    yarn : int array (m,), optional
        Yarn id of each element (default 0). Used to name culprits in errors and by contact.
    semi_axes : array (m, 2) or (2,), optional
        Semi-axes (a along e2, b along e3) of elliptical sections, mm.
    ref : array (m, 3) or (3,), optional
        Reference vectors fixing the local e2 axis (e2 = part of ref normal to e1).
        Default: global z, or global x for elements within ~25 degrees of z.
    periods : array (k, 3), optional
        Lattice vectors of a periodic frame (k = 1, 2 or 3), mm.
    images : int array (m, k), optional
        Image offsets: element e joins node i to node j + images[e] @ periods.
    contact_radius : float or array (m,), optional
        Radius for contact, mm; default the section radius (larger semi-axis).
    prestrain : float or array (m,), optional
        Initial axial shortening strain eps0: the element wants to be shorter by
        eps0 (positive values pre-stress it in tension when its ends are held).
    bending_factor, torsion_factor : float or array (m,), optional
        Multiply the bending second moments Iy, Iz and the torsion constant J of the section
        (default 1: the solid section). A multifilament bundle bends and twists more easily
        than a solid rod of its section (its fibres slide) and more stiffly than its fibres
        alone; the axial stiffness stays that of the section.
    strain_limit : float or array (m,), optional
        Largest axial or shear strain the element is trusted to (default
        :data:`~homtex.model.sections.DEFAULT_STRAIN_LIMIT` = 0.02). The beam is linear elastic in
        small strains (large rotations are exact in the co-rotational solve); the large-rotation
        solver warns and records when a state goes beyond it. 0.02 because polyester and polyamide
        fibres leave their linear elastic range at about 1.5-3 % strain, and at 2 % the engineering
        strain of the element differs from the Green-Lagrange strain of a finite-strain rod by 1 %
        of itself (eps / 2), the error the small-strain element makes there.
    """

    def __init__(self, nodes, elements, *, radius=None, E=None, nu=None, yarn=None,
                 semi_axes=None, ref=None, periods=None, images=None,
                 contact_radius=None, prestrain=None, bending_factor=None, torsion_factor=None,
                 strain_limit=None):
        self._topology(nodes, elements)
        m = len(self.elements)
        self._periodicity(periods, images, m)
        self._sections(radius, semi_axes, E, nu, yarn, contact_radius, prestrain, bending_factor, torsion_factor, m)
        self.strain_limit = per_element(DEFAULT_STRAIN_LIMIT if strain_limit is None else strain_limit, m,
                                        "strain_limit", positive=True, limit=1.0, yarn=self.yarn)
        self._local_frames(ref, m)
        props = section_properties(self.a, self.b, self.nu)
        self.A, self.Iy, self.Iz, self.J, self.k = (props[x] for x in ("A", "Iy", "Iz", "J", "k"))
        self.Iy = np.ascontiguousarray(self.Iy * self.bending_factor)
        self.Iz = np.ascontiguousarray(self.Iz * self.bending_factor)
        self.J = np.ascontiguousarray(self.J * self.torsion_factor)
        self.G = self.E / (2.0 * (1.0 + self.nu))

    def _topology(self, nodes, elements):
        raw = to_array(nodes, "nodes")
        if raw.dtype.kind in "iuf" and raw.ndim == 2 and raw.shape[1:] == (3,):
            bad = ~np.isfinite(raw).all(axis=1)
            if bad.any():
                i = _first_bad(bad)
                raise InputError(f"node {i} has a non-finite coordinate {raw[i].tolist()} "
                                 f"({int(bad.sum())} such nodes)")
        nodes = as_real(nodes, "nodes", width=3, limit=MAX_COORD)
        n = len(nodes)
        arr = to_array(elements, "elements")
        if arr.ndim != 2 or arr.shape[1] != 2:
            raise InputError(f"elements must have shape (m, 2), got {np.shape(arr)}")
        if len(arr) == 0:
            raise InputError("a frame needs at least one element")
        elements = as_index(arr, "elements")
        out = (elements < 0) | (elements >= n)
        if out.any():
            e = _first_bad(out.any(axis=1))
            raise InputError(f"element {e} refers to node {elements[e].tolist()}, "
                             f"outside 0..{n - 1}")
        self.nodes = nodes
        self.elements = elements

    def _periodicity(self, periods, images, m):
        if periods is None:
            periods = np.zeros((0, 3))
        periods = as_real(periods, "periods", limit=MAX_COORD)
        if periods.shape == (3,):
            periods = periods[None]
        if periods.ndim != 2 or periods.shape[1] != 3 or len(periods) > 3:
            raise InputError(f"periods must have shape (k, 3) with k = 1, 2 or 3 lattice vectors (mm), got "
                             f"{periods.shape}")
        k = len(periods)
        if k and np.linalg.matrix_rank(periods, tol=1e-9 * max(1.0, np.abs(periods).max())) < k:
            raise InputError(f"periods: the {k} lattice vectors {periods.tolist()} are not linearly independent")
        if images is None:
            if k:
                raise InputError("images: a periodic frame needs an (m, k) integer image offset per element")
            images = np.zeros((m, 0), dtype=np.int64)
        images = as_index(images, "images", lo=-10 ** 6, hi=10 ** 6)
        if images.ndim == 1 and k == 1:
            images = images[:, None]
        if images.shape != (m, k):
            raise InputError(f"images must have shape ({m}, {k}), got {images.shape}")
        self.periods = periods
        self.images = np.ascontiguousarray(images)
        if k and np.abs(self.element_vectors).max() > MAX_COORD:
            raise InputError(f"images: element vectors reach {np.abs(self.element_vectors).max():.3g} mm "
                             f"(limit {MAX_COORD:g} mm): an image offset far larger than the cell")

    def _sections(self, radius, semi_axes, E, nu, yarn, contact_radius, prestrain, bending_factor,
                  torsion_factor, m):
        self.yarn = per_element(0 if yarn is None else yarn, m, "yarn", index=True, lo=0, hi=2 ** 31 - 1)
        y = self.yarn
        if semi_axes is not None:
            sa = as_real(semi_axes, "semi_axes", limit=MAX_COORD)
            if sa.shape == (2,):
                sa = np.broadcast_to(sa, (m, 2))
            if sa.shape != (m, 2):
                raise InputError(f"semi_axes must have shape (2,) or ({m}, 2), got {sa.shape}")
            self.a = per_element(sa[:, 0], m, "semi-axis a (semi_axes[:, 0])", lo=MIN_RADIUS, yarn=y)
            self.b = per_element(sa[:, 1], m, "semi-axis b (semi_axes[:, 1])", lo=MIN_RADIUS, yarn=y)
        else:
            if radius is None:
                raise InputError("radius (circular sections) or semi_axes (elliptical sections) is required, mm")
            r = per_element(radius, m, "radius", positive=True, lo=MIN_RADIUS, limit=MAX_COORD, yarn=y)
            self.a, self.b = r, r.copy()
        self.E = per_element(E, m, "E", positive=True, limit=MAX_MODULUS, yarn=y)
        self.nu = per_element(nu, m, "nu", lo=-1.0, hi=0.5, yarn=y)
        self.contact_radius = (np.maximum(self.a, self.b) if contact_radius is None
                               else per_element(contact_radius, m, "contact_radius", positive=True,
                                                lo=MIN_RADIUS, limit=MAX_COORD, yarn=y))
        # an axial pre-strain of 1 would shrink the element to nothing
        self.prestrain = per_element(0.0 if prestrain is None else prestrain, m, "prestrain", lo=-1.0, hi=1.0,
                                     yarn=y)
        # bounded below too: a subnormal factor (5e-324) underflows the rigidity to zero
        self.bending_factor = per_element(1.0 if bending_factor is None else bending_factor, m, "bending_factor",
                                          positive=True, lo=1.0 / MAX_FACTOR, limit=MAX_FACTOR, yarn=y)
        self.torsion_factor = per_element(1.0 if torsion_factor is None else torsion_factor, m, "torsion_factor",
                                          positive=True, lo=1.0 / MAX_FACTOR, limit=MAX_FACTOR, yarn=y)

    def _local_frames(self, ref, m):
        d = self.element_vectors
        L = np.linalg.norm(d, axis=1)
        scale = max(1.0, float(np.abs(self.nodes).max()) if len(self.nodes) else 1.0)
        bad = L <= 1e-12 * scale
        if bad.any():
            e = _first_bad(bad)
            raise InputError(f"element {e} (yarn {self.yarn[e]}, nodes {self.elements[e].tolist()}) has zero "
                             "length")
        self._check_duplicates()
        e1 = d / L[:, None]
        if ref is None:
            ref = np.zeros((m, 3))
            ref[:, 2] = 1.0
            near_z = np.abs(e1[:, 2]) > 0.9
            ref[near_z] = (1.0, 0.0, 0.0)
        ref = as_real(ref, "ref")
        if ref.shape == (3,):
            ref = np.broadcast_to(ref, (m, 3))
        if ref.shape != (m, 3):
            raise InputError(f"ref must have shape (3,) or ({m}, 3), got {ref.shape}")
        e2 = ref - np.einsum("ij,ij->i", ref, e1)[:, None] * e1
        n2 = np.linalg.norm(e2, axis=1)
        rn = np.linalg.norm(ref, axis=1)
        bad = ~(n2 > 1e-8 * np.maximum(rn, 1e-300))
        if bad.any():
            e = _first_bad(bad)
            raise InputError(f"reference vector {ref[e].tolist()} of element {e} (yarn {self.yarn[e]}) "
                             f"is parallel to the element (or zero)")
        e2 /= n2[:, None]
        e3 = np.cross(e1, e2)
        self.length = np.ascontiguousarray(L)
        # rotation matrices: rows e1, e2, e3 (global -> local)
        self.R = np.ascontiguousarray(np.stack([e1, e2, e3], axis=1))

    # ------------------------------------------------------------------
    def _check_duplicates(self):
        el = self.elements
        img = self.images
        swap = el[:, 0] > el[:, 1]
        lo = np.where(swap, el[:, 1], el[:, 0])
        hi = np.where(swap, el[:, 0], el[:, 1])
        img_c = np.where(swap[:, None], -img, img)
        # a self-loop (i == i + image) reversed is the same strut with -image
        # a self-loop (i -> i + image) read backwards is the same strut with -image:
        # canonical sign makes the first non-zero image component positive
        same = lo == hi
        if same.any() and img.shape[1]:
            first = np.zeros(len(el), dtype=np.int64)
            for c in range(img.shape[1] - 1, -1, -1):
                first = np.where(img_c[:, c] != 0, img_c[:, c], first)
            flip = same & (first < 0)
            img_c = np.where(flip[:, None], -img_c, img_c)
        key = np.column_stack([lo, hi, img_c])
        _, idx, inv, cnt = np.unique(key, axis=0, return_index=True, return_inverse=True, return_counts=True)
        if (cnt > 1).any():
            g = _first_bad(cnt > 1)
            dup = np.flatnonzero(inv.ravel() == g)
            raise InputError(f"elements {dup[0]} and {dup[1]} are duplicates: both join nodes "
                             f"{el[dup[0]].tolist()} (yarn {self.yarn[dup[0]]})")

    # ------------------------------------------------------------------
    @property
    def n_nodes(self) -> int:
        return len(self.nodes)

    @property
    def n_elements(self) -> int:
        return len(self.elements)

    @property
    def ndof(self) -> int:
        return 6 * len(self.nodes)

    @property
    def dim_periodic(self) -> int:
        """Number of lattice vectors k (0 for a non-periodic frame)."""
        return len(self.periods)

    @property
    def shift(self) -> np.ndarray:
        """(m, 3) offset added to the second node of each element, mm."""
        return self.images @ self.periods if self.periods.size else np.zeros((len(self.elements), 3))

    @property
    def element_vectors(self) -> np.ndarray:
        """(m, 3) vector from the first to the (shifted) second node, mm."""
        return self.nodes[self.elements[:, 1]] + self.shift - self.nodes[self.elements[:, 0]]

    @cached_property
    def EA(self):
        """(m,) axial stiffness E A, N."""
        return self.E * self.A

    @cached_property
    def node_radius(self) -> np.ndarray:
        """(n,) largest contact radius of the elements at each node, mm (node-plate gaps use it)."""
        r = np.zeros(self.n_nodes)
        np.maximum.at(r, self.elements[:, 0], self.contact_radius)
        np.maximum.at(r, self.elements[:, 1], self.contact_radius)
        return r

    def yarn_ids(self):
        return np.unique(self.yarn)

    # ------------------------------------------------------------------ the one copy path
    def element_fields(self, select=None) -> dict:
        """The per-element constructor arguments of this frame ({name: (m, ...) array}).

        ``select``: element indices or a bool mask; an index array may repeat elements (tiling).
        Every copy of a frame (``with_``, tiling, periodising, joining with a stitch) goes
        through here, so a new per-element field is added in :data:`ELEMENT_FIELDS` and here only.
        """
        d = {"semi_axes": np.column_stack([self.a, self.b]), "E": self.E, "nu": self.nu, "yarn": self.yarn,
             "ref": self.R[:, 1], "contact_radius": self.contact_radius, "prestrain": self.prestrain,
             "bending_factor": self.bending_factor, "torsion_factor": self.torsion_factor,
             "strain_limit": self.strain_limit}
        assert tuple(d) == ELEMENT_FIELDS
        if select is not None:
            d = {k: v[select] for k, v in d.items()}
        return {k: np.ascontiguousarray(v) for k, v in d.items()}

    def with_(self, **changes) -> "Frame":
        """A copy with some constructor arguments replaced (e.g. ``prestrain=...``)."""
        kw = dict(nodes=self.nodes, elements=self.elements, periods=self.periods, images=self.images,
                  **self.element_fields())
        kw.update(changes)
        if "radius" in changes:
            kw.pop("semi_axes")
        return Frame(**kw)

    replace = with_

    def __repr__(self) -> str:
        per = f", {self.dim_periodic}-periodic" if self.dim_periodic else ""
        return (f"Frame({self.n_nodes} nodes, {self.n_elements} elements, "
                f"{len(self.yarn_ids())} yarns{per})")


def stack_fields(*parts: dict) -> dict:
    """Per-element fields of frames joined one after another ({name: array}); a field missing
    from a part takes the Frame default for that part's elements (zero pre-strain, factors 1).
    Fields without a default (section, E, nu, yarn, reference vector) must be in every part."""
    sizes = [len(next(iter(p.values()))) for p in parts]
    out = {}
    for name in ELEMENT_FIELDS:
        cols = []
        for p, m in zip(parts, sizes):
            if name in p:
                cols.append(np.asarray(p[name]))
            elif name in FIELD_DEFAULTS:
                cols.append(np.full(m, FIELD_DEFAULTS[name]))
            else:
                raise InputError(f"stack_fields: field {name!r} is missing from a part (no default)")
        out[name] = np.concatenate(cols)
    return out
