"""Lattice vectors as unknowns of the large-motion engine (``homtex.Lattice``).

A periodic frame joins node i to node j shifted by ``images[e] @ periods``; here the periods
(k, 3) (mm) move: each lattice vector is an extra "node" of the engine whose three translations
are the vector's change. A component is held (default), prescribed (``motion``, mm at load
factor 1: a macro stretch), or free (zero generalised force: free lateral contraction, a cell
relaxing to its own size), optionally loaded by a dead force (``force``, N at load factor 1:
a take-down tension). The generalised force on a lattice component, dPi / da, is the force the
cell transmits across its boundary: for a 2-periodic fabric cell stretched along a2, the force
on a2 over the width |a1| is the force per unit width of the fabric.

How the rest of the engine sees it (:class:`LatticeDriver`):

* elements: the co-rotational kernels take the current shifts; the element force on the shifted
  end, times the image, is the lattice gradient; the element tangent's columns of that end, times
  the image, couple the lattice to the nodes;
* contact: every periodic image of a node that a contact stencil needs is a *virtual node* (its
  position x_j + image @ periods), appended after the frame's nodes and kept for the whole solve
  (friction lags refer to it); the barrier, friction and the continuous collision check run on
  these positions unchanged, so every state stays intersection-free while the lattice moves; the
  broad phase searches with the current periods. Gradients and Hessian blocks on virtual nodes
  fold back onto their nodes and onto the lattice (chain rule, exact);
* the linear system: the lattice DOFs border the nodes' free system
  (:class:`~homtex.contact.lattice_system.BorderedSystem`, a Schur complement of at most 9
  unknowns), so the nodes' tangent keeps its pattern and factorisation.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError, SolverError
from .ipc_scene import ContactScene

__all__ = ["Lattice", "LatticeDriver", "LatticeScene"]


def _pairs(spec, name: str, k: int, values: bool) -> dict:
    """{(vector, component): value} from a dict (values) or an iterable of pairs."""
    out = {}
    items = spec.items() if values else ((p, None) for p in spec)
    for key, v in items:
        try:
            a, c = (int(q) for q in key)
        except (TypeError, ValueError):
            raise InputError(f"Lattice.{name}: keys are (vector, component) pairs of integers, got {key!r}") from None
        if not (0 <= a < k and 0 <= c < 3):
            raise InputError(f"Lattice.{name}: ({a}, {c}) is not a component of the {k} lattice vector(s) "
                             "(vector 0..k-1, component 0..2 = x, y, z)")
        if values:
            v = float(v)
            if not np.isfinite(v):
                raise InputError(f"Lattice.{name}[({a}, {c})] must be finite, got {v!r}")
        out[(a, c)] = v
    return out


@dataclass
class Lattice:
    """The periodic frame's lattice vectors as unknowns (see the module docstring).

    Parameters
    ----------
    free : (vector, component) pairs left free (zero generalised force unless ``force`` loads
        them).
    motion : {(vector, component): change at load factor 1, mm}: prescribed components.
    force : {(vector, component): dead force at load factor 1, N}: on free components.

    Components named nowhere are held at their start values (fix the ones that would rotate the
    cell rigidly: for a 2-periodic fabric in the xy plane with a1 along x, hold a1's y and both z).
    """

    free: tuple = ()
    motion: dict = field(default_factory=dict)
    force: dict = field(default_factory=dict)

    def arrays(self, k: int):
        """(held (k, 3) bool, motion (k, 3) mm, force (k, 3) N), checked against k lattice vectors."""
        if k == 0:
            raise InputError("lattice: the frame is not periodic (no lattice vectors to move)")
        free = _pairs(self.free, "free", k, False)
        motion = _pairs(self.motion, "motion", k, True)
        force = _pairs(self.force, "force", k, True)
        both = sorted(set(free) & set(motion))
        if both:
            raise InputError(f"Lattice: component {both[0]} is both free and prescribed")
        bad = sorted(set(force) - set(free))
        if bad:
            raise InputError(f"Lattice.force: component {bad[0]} is not free (a dead force acts on a free component)")
        held = np.ones((k, 3), dtype=bool)
        for a, c in free:
            held[a, c] = False
        mo = np.zeros((k, 3))
        for (a, c), v in motion.items():
            mo[a, c] = v
        fo = np.zeros((k, 3))
        for (a, c), v in force.items():
            fo[a, c] = v
        return held, mo, fo

    @classmethod
    def in_plane(cls, *, stretch: tuple | None = None, force: dict | None = None) -> "Lattice":
        """A 2-periodic fabric in the xy plane with a1 along x: a1.x, a2.x and a2.y free (the cell
        relaxes its size and shear), a1.y and the z components held (rigid rotations). ``stretch``
        = (vector, mm): that vector's in-plane length component (a1.x or a2.y) prescribed instead."""
        free = {(0, 0), (1, 0), (1, 1)}
        motion = {}
        if stretch is not None:
            v, mm = int(stretch[0]), float(stretch[1])
            key = (0, 0) if v == 0 else (1, 1)
            free.discard(key)
            motion[key] = mm
        return cls(free=tuple(sorted(free)), motion=motion, force=dict(force or {}))


# ---------------------------------------------------------------------------------------------
class LatticeDriver:
    """The moving lattice inside an :class:`~homtex.contact.incremental.IncrementalSolver`.

    Parameters
    ----------
    frame : the periodic Frame. control : :class:`Lattice`. row0 : first row of the lattice
        "nodes" in the solver's (N, 6) arrays. periods : the start periods (default the frame's).
    """

    def __init__(self, frame, control: Lattice, row0: int, periods=None):
        self.k = frame.dim_periodic
        self.held, self.motion, self.force = control.arrays(self.k)
        self.n = frame.n_nodes
        self.rows = row0 + np.arange(self.k)
        self.periods = np.array(frame.periods if periods is None else periods, dtype=float).reshape(self.k, 3)
        self.path_start = self.periods.copy()
        self.images = np.ascontiguousarray(frame.images, dtype=np.int64)
        self.img_el = np.flatnonzero(np.any(self.images != 0, axis=1))
        self.base = np.zeros(0, dtype=np.int64)
        self.img = np.zeros((0, self.k), dtype=np.int64)
        self._codes = np.zeros(0, dtype=np.int64)     # sorted codes of the registered (node, image) keys
        self._ids = np.zeros(0, dtype=np.int64)       # their virtual node numbers (- n)
        self.target = self.periods.copy()

    # ------------------------------------------------------------------ virtual nodes
    @property
    def n_ext(self) -> int:
        """Number of contact positions: the frame's nodes and the virtual ones."""
        return self.n + len(self.base)

    def shifts(self, periods=None) -> np.ndarray:
        """(m, 3) element shifts images @ periods (mm)."""
        return self.images @ (self.periods if periods is None else periods)

    def xc(self, x: np.ndarray, periods=None) -> np.ndarray:
        """(n + V, 3) contact positions: nodes x (n, 3), then the virtual nodes."""
        p = self.periods if periods is None else periods
        return np.ascontiguousarray(np.vstack([x, x[self.base] + self.img @ p]))

    def disp(self, d: np.ndarray) -> np.ndarray:
        """(n + V, 3) motion of the contact positions for a step d (N, 6) of the solver's DOFs."""
        da = d[self.rows, :3]
        return np.ascontiguousarray(np.vstack([d[:self.n, :3], d[self.base, :3] + self.img @ da]))

    def fold(self, gc: np.ndarray, g: np.ndarray) -> None:
        """Add a gradient on the contact positions gc (n + V, 3) to g (N, 6) (nodes and lattice)."""
        g[:self.n, :3] += gc[:self.n]
        if len(self.base):
            gv = gc[self.n:]
            np.add.at(g[:self.n, :3], self.base, gv)
            g[self.rows, :3] += self.img.T @ gv

    def real(self, nodes: np.ndarray) -> np.ndarray:
        """Node indices of contact positions (virtual -> the node it copies)."""
        nodes = np.asarray(nodes, dtype=np.int64)
        if not len(self.base):
            return nodes
        return np.where(nodes >= self.n, self.base[np.clip(nodes - self.n, 0, None)], nodes)

    def images_of(self, nodes: np.ndarray) -> np.ndarray:
        """(..., k) image of each contact position (0 for the frame's nodes)."""
        nodes = np.asarray(nodes, dtype=np.int64)
        out = np.zeros(nodes.shape + (self.k,), dtype=np.int64)
        v = nodes >= self.n
        if v.any():
            out[v] = self.img[nodes[v] - self.n]
        return out

    def remap(self, st) -> None:
        """Point every stencil slot that sits in a periodic image at its virtual node (registered
        once for the whole solve) and zero its shift: the stencil then reads positions from
        :meth:`xc`, which follow the lattice."""
        if not len(st):
            return
        el_img = self.images
        slot_img = np.zeros((len(st), 4, self.k), dtype=np.int64)
        slot_img[:, 1] = el_img[st.a]
        slot_img[:, 2] = st.image
        slot_img[:, 3] = st.image + el_img[st.b]
        hit = np.any(slot_img != 0, axis=2)
        q, s = np.nonzero(hit)
        nodes = st.nodes
        node, img = nodes[q, s].astype(np.int64), slot_img[q, s]
        code = self._code(node, img)
        # register the keys seen for the first time, in order of first appearance
        uc, first = np.unique(code, return_index=True)
        pos = np.searchsorted(self._codes, uc)
        known = (pos < len(self._codes)) & (self._codes[np.minimum(pos, len(self._codes) - 1)] == uc) \
            if len(self._codes) else np.zeros(len(uc), dtype=bool)
        if not known.all():
            fresh = np.sort(first[~known])                      # hit indices, first appearance first
            ids = len(self.base) + np.arange(len(fresh))
            self.base = np.r_[self.base, node[fresh]]
            self.img = np.vstack([self.img, img[fresh]])
            codes = np.r_[self._codes, code[fresh]]
            order = np.argsort(codes, kind="stable")
            self._codes, self._ids = codes[order], np.r_[self._ids, ids][order]
        nodes[q, s] = self.n + self._ids[np.searchsorted(self._codes, code)]
        st.shift[hit] = 0.0

    def _code(self, node: np.ndarray, img: np.ndarray) -> np.ndarray:
        """One int64 per (node, image) key (images within +-2047 periods, nodes below 2**62 / 4096**k)."""
        if len(img) and np.abs(img).max() > 2047:
            raise SolverError(f"a contact reaches {int(np.abs(img).max())} periods away from its cell: the "
                              "lattice has collapsed (a period near zero)")
        code = node.copy()
        for i in range(self.k):
            code = code * 4096 + (img[:, i] + 2048)
        return code

    # ------------------------------------------------------------------ elements
    def element_grad(self, fe: np.ndarray) -> np.ndarray:
        """(k, 3) gradient of the beam energy on the lattice: sum_e images[e] (x) force on the
        shifted end (fe (m, 2, 6), N)."""
        e = self.img_el
        return self.images[e].T @ fe[e, 1, :3]

    def element_hess_times(self, Ke: np.ndarray, d: np.ndarray, out: np.ndarray, elements: np.ndarray) -> None:
        """Add the lattice part of the beam tangent times a step d (N, 6) to out (N, 6): the
        columns of the shifted ends times image @ d_lattice on the nodes, and the rows of the
        shifted ends times the elements' full step on the lattice."""
        e = self.img_el
        if not len(e):
            return
        K = 0.5 * (Ke[e] + np.transpose(Ke[e], (0, 2, 1)))
        W = self.images[e].astype(float)
        dl = W @ d[self.rows, :3]                                   # (me, 3)
        el = elements[e]
        extra = np.einsum("eac,ec->ea", K[:, :, 6:9], dl)           # (me, 12)
        np.add.at(out[:, :], el[:, 0], extra[:, :6])
        np.add.at(out[:, :], el[:, 1], extra[:, 6:])
        de = np.concatenate([d[el[:, 0]], d[el[:, 1]]], axis=1)
        de[:, 6:9] += dl
        y = np.einsum("eca,ea->ec", K[:, 6:9, :], de)                # (me, 3)
        out[self.rows, :3] += W.T @ y

    # ------------------------------------------------------------------ state
    def loads(self, scale: float) -> np.ndarray:
        """(k, 3) dead forces on the lattice at load factor ``scale`` (N)."""
        return scale * self.force

    def set_target(self, motion: float) -> None:
        """Prescribed components at motion factor ``motion`` (from the path's start)."""
        self.target = np.where(self.held, self.path_start + motion * self.motion, self.periods)

    def remaining(self) -> np.ndarray:
        """(k, 3) prescribed motion left to the target (0 on free components)."""
        return np.where(self.held, self.target - self.periods, 0.0)

    def reach_target(self) -> None:
        self.periods[self.held] = self.target[self.held]

    @property
    def driven(self) -> bool:
        return bool(np.any(self.motion != 0.0) or np.any(self.force != 0.0))


class LatticeScene(ContactScene):
    """A :class:`~homtex.contact.ipc_scene.ContactScene` over a moving lattice: the broad phase
    searches with the current periods and the stencils read the virtual nodes of ``driver``;
    :meth:`search`, :meth:`moved` and :meth:`covers` take the frame's node positions (n, 3), the
    potentials the contact positions of :meth:`LatticeDriver.xc`."""

    def __init__(self, *args, driver: LatticeDriver, **kw):
        self.driver = driver
        super().__init__(*args, **kw)

    def search(self, x: np.ndarray, margin: float | None = None) -> None:
        x = np.asarray(x)[:self.n]
        self.broad.periods = np.ascontiguousarray(self.driver.periods)
        super().search(x, margin)
        self.driver.remap(self.stencil)
        self.x_search = self.driver.xc(x)
        self.p_search = self.driver.periods.copy()

    def moved(self, x: np.ndarray) -> float:
        """Largest motion since the search of any point that can come into contact: the contact
        positions, and every node seen from a neighbouring cell (its motion plus the lattice's)."""
        if self.x_search is None:
            return np.inf
        x = np.asarray(x)[:self.n]
        xc = self.driver.xc(x)
        if len(xc) != len(self.x_search):
            return np.inf
        d = xc - self.x_search
        dn = np.sqrt(np.einsum("ij,ij->i", d[:self.n], d[:self.n])).max(initial=0.0)
        return float(max(np.sqrt(np.einsum("ij,ij->i", d, d)).max(initial=0.0),
                         dn + image_motion(self.driver.periods - self.p_search)))


def image_motion(dP: np.ndarray) -> float:
    """How far a neighbouring cell's copy of a node can move relative to the node for a change dP
    (k, 3) of the lattice: the sum of the vectors' changes (images one cell away)."""
    return float(np.linalg.norm(dP, axis=1).sum())


class LatticeMixin:
    """What :class:`~homtex.contact.incremental.IncrementalSolver` calls where the lattice may
    move: contact positions, their motion, gradients folded back, node indices and border blocks
    (with ``self.lat`` None, the frame's nodes as they are)."""

    lat: LatticeDriver | None = None
    _p_start = None                     # the lattice at the start of the step (friction's slips)

    def _xc(self, x: np.ndarray, periods=None) -> np.ndarray:
        """Contact positions (n + V, 3) of node positions x (n, 3) (and the lattice's periods)."""
        return x if self.lat is None else self.lat.xc(x, periods)

    def _disp_c(self, d: np.ndarray) -> np.ndarray:
        """Motion (n + V, 3) of the contact positions for a step d (N, 6)."""
        return d[:self.n, :3] if self.lat is None else self.lat.disp(d)

    def _fold(self, gc: np.ndarray, g: np.ndarray) -> None:
        """Add a gradient on the contact positions to g (N, 6)."""
        if self.lat is None:
            g[:self.n, :3] += gc
        else:
            self.lat.fold(gc, g)

    def _real(self, nodes: np.ndarray) -> np.ndarray:
        return nodes if self.lat is None else self.lat.real(nodes)

    def _n_contact(self) -> int:
        return self.n if self.lat is None else self.lat.n_ext

    def _lattice_blocks(self, H, nodes) -> None:
        if self.lat is not None and H is not None and len(H):
            self.sys.add_lattice_blocks(H, nodes)

    def _lattice_loads(self) -> np.ndarray:
        """(k, 3) dead forces on the lattice at the current load factor (N)."""
        return np.zeros((0, 3)) if self.lat is None else self.lat.loads(self.load_scale)

    def _set_periods(self, periods: np.ndarray) -> None:
        self.lat.periods[...] = periods
        self.cor.shift[...] = self.lat.shifts()
