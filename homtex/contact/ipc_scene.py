"""The scene of the large-motion contact engine: a frame, rigid plates, the candidate contacts
and the contact and friction potentials over them (:class:`ContactScene`).

Contacts are those of :mod:`homtex.contact.potential` (yarn-yarn: segment-segment distances
with the radii as offsets, near-parallel pairs by nodal quadrature, an inclusion-exclusion that
counts every contact point once) and :mod:`homtex.contact.plates` (node-plane gaps with the node's
contact radius), enforced by the IPC log barrier, so every state must be intersection-free.
Rigid plates are planes normal to z; plate p is an extra node n + p whose uz is its height
(free under force control), so a plate's contact blocks couple the node with the plate.

Candidates come from the uniform-grid broad phase (:class:`~homtex.contact.broad.BroadPhase`,
periodic images included) with the same-yarn filter by arc length
(:func:`~homtex.model.exclusions.arc_exclusions`), searched with a margin; the scene tracks how
far nodes moved since the search, and the engine searches again before a step could reach a
pair outside the list.

Pairs that touch (gap below ghat) or overlap in the reference geometry (a generator's
artefact) count as touching at gap ghat: their sum of radii is reduced so that their barrier
starts at zero force (``touch`` offsets, kept by pair identity for the whole solve).

Friction coefficients: per element yarn type, a (T, T) table between types and (T,) against
plates (:func:`friction_setup`: ``Contact(friction=...)``, else a cell file's ``[contact]``
table, else 0).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, replace

import numpy as np

from ..errors import InputError
from ..model.exclusions import arc_exclusions
from .broad import BroadPhase
from .constraints import pair_keys
from .friction import FrictionLag, pair_friction_lag, plate_friction_lag
from .options import Contact
from .potential import Enforcement, pair_potential
from .stencil import frame_stencil

log = logging.getLogger(__name__)

__all__ = ["ContactScene", "PlateState", "friction_setup"]


@dataclass
class PlateState:
    """Rigid plates normal to z: ``z`` (P,) current heights (mm), ``normal`` (P,) +1 (yarns
    above: a bottom plate) or -1 (yarns below), ``force_controlled`` (P,) bool."""

    z: np.ndarray
    normal: np.ndarray
    force_controlled: np.ndarray

    def __len__(self):
        return len(self.z)

    def origins(self, z=None) -> np.ndarray:
        zz = self.z if z is None else z
        return np.column_stack([np.zeros(len(zz)), np.zeros(len(zz)), zz])

    def normals(self) -> np.ndarray:
        return np.column_stack([np.zeros(len(self.z)), np.zeros(len(self.z)), self.normal.astype(float)])


def friction_setup(frame, contact: Contact, spec: dict | None = None) -> tuple:
    """(types (m,) int, table (T, T), plate (T,)): friction coefficients per element yarn type.

    ``contact.friction`` (when not None) applies to every pair, ``contact.plate_friction`` to the
    plates; else the cell file's ``spec`` (:meth:`homtex.Cell.friction_spec`), else 0.
    """
    m = frame.n_elements
    if contact.friction is not None or spec is None:
        mu = float(contact.friction or 0.0)
        pmu = mu if contact.plate_friction is None else float(contact.plate_friction)
        return np.zeros(m, dtype=np.int64), np.full((1, 1), mu), np.full(1, pmu)
    types = np.asarray(spec["types"], dtype=np.int64)
    if types.shape != (m,):
        raise InputError(f"friction spec: types must have shape ({m},), got {types.shape}")
    plate = np.asarray(spec["plate"], dtype=float).copy()
    if contact.plate_friction is not None:
        plate[:] = float(contact.plate_friction)
    return types, np.asarray(spec["table"], dtype=float), plate


class ContactScene:
    """Candidates and contact potentials of a frame between rigid plates.

    Parameters
    ----------
    frame : homtex.Frame (finite or 1-, 2-periodic).
    plates : :class:`PlateState` (may be empty).
    pair_enf, plate_enf : :class:`~homtex.contact.potential.Enforcement` of yarn-yarn and
        yarn-plate contact (barrier).
    friction : (types, table, plate) from :func:`friction_setup`.
    margin : search margin, mm (> ghat): pairs whose surfaces are farther apart than this at
        the search are left out until the next search.
    touch : (keys, rsum, gap) of the pairs found touching in the reference geometry by an earlier
        scene of the same frame (a continued solve); default: found here from the frame's nodes.
    core : shell thickness of compressible yarns, mm (default 0): gaps are measured from the cores
        (contact radius - core) and the enforcement's shell law acts over the shells.
    """

    def __init__(self, frame, plates: PlateState, pair_enf: Enforcement, plate_enf: Enforcement,
                 friction: tuple, margin: float, touch: tuple | None = None, core: float = 0.0):
        self.frame = frame
        self.n = frame.n_nodes
        self.plates = plates
        self.P = len(plates)
        self.pair_enf = pair_enf
        self._exact = replace(pair_enf, project=False)
        self.plate_enf = plate_enf
        self.types, self.mu_table, self.mu_plate_type = friction
        r = frame.contact_radius
        self.margin = float(margin)
        self.core = float(core)
        excl = arc_exclusions(frame, max(float(r.max()), 2.0 * pair_enf.ghat))
        self.broad = BroadPhase(frame.elements, r, frame.periods, frame.images, excl)
        self.node_r = np.ascontiguousarray(frame.node_radius - self.core)
        # yarn type of each node (its first element) for the plate friction
        nt = np.zeros(self.n, dtype=np.int64)
        nt[frame.elements[::-1, 1]] = self.types[::-1]
        nt[frame.elements[::-1, 0]] = self.types[::-1]
        self.mu_plate = np.ascontiguousarray(self.mu_plate_type[nt])
        self.has_friction = bool(self.mu_table.max(initial=0.0) > 0 or self.mu_plate.max(initial=0.0) > 0)
        # plate candidates: every node against every plate
        self.plate_nodes = np.tile(np.arange(self.n, dtype=np.int64), self.P)
        self.plate_index = np.repeat(np.arange(self.P, dtype=np.int64), self.n)
        self.touch_keys = np.zeros(0, dtype=np.int64)
        self.touch_rsum = np.zeros(0)
        self.touch_gap = np.zeros(0)
        self.stencil = None
        self.x_search = None
        self.searches = 0
        if touch is None:
            self._touching(frame.nodes)
        else:                   # a continued solve keeps the pairs its first solve found touching
            self.touch_keys, self.touch_rsum, self.touch_gap = (np.array(t, copy=True) for t in touch)

    # ------------------------------------------------------------------ candidates
    def _keys(self, pr) -> np.ndarray:
        img = np.asarray(pr["image"], dtype=np.int64).reshape(len(pr["a"]), -1)
        return pair_keys(np.asarray(pr["a"]), np.asarray(pr["b"]), img, self.frame.n_elements)

    def _touching(self, x0):
        """Reference pairs closer than ghat: their sum of radii is reduced to distance - ghat."""
        pr = self.broad.pairs(x0, self.pair_enf.ghat)
        if not len(pr["a"]):
            return
        st = frame_stencil(self.frame, pr)
        st.rsum -= 2.0 * self.core
        gap = pair_potential(x0, st, Enforcement("penalty", ghat=self.pair_enf.ghat, kappa=1.0), hessian=False).gap
        close = gap < self.pair_enf.ghat
        keys = self._keys(pr)[close]
        order = np.argsort(keys)
        self.touch_keys = keys[order]
        self.touch_rsum = (st.rsum[close] + gap[close] - self.pair_enf.ghat)[order]
        self.touch_gap = gap[close][order]
        if len(keys):
            log.info("%d yarn pairs touch or overlap in the reference geometry (min gap %.3g mm): they start "
                     "touching at gap ghat", len(keys), float(gap[close].min()))

    @property
    def initial_touching(self) -> int:
        return int(len(self.touch_keys))

    def search(self, x: np.ndarray, margin: float | None = None) -> None:
        """Candidate pairs at positions x (n, 3) within ``margin`` (default the scene's)."""
        margin = self.margin if margin is None else float(margin)
        pr = self.broad.pairs(x, margin)
        st = frame_stencil(self.frame, pr)
        st.rsum -= 2.0 * self.core
        if len(self.touch_keys) and len(st):
            keys = self._keys(pr)
            pos = np.minimum(np.searchsorted(self.touch_keys, keys), len(self.touch_keys) - 1)
            hit = self.touch_keys[pos] == keys
            st.rsum[hit] = self.touch_rsum[pos[hit]]
        self.stencil = st
        ta, tb = self.types[st.a], self.types[st.b]
        self.mu_pair = np.ascontiguousarray(self.mu_table[ta, tb])
        self.x_search = np.array(x, dtype=float, copy=True)
        self.search_margin = margin
        self.searches += 1

    def moved(self, x: np.ndarray) -> float:
        """Largest node motion since the last search (mm)."""
        if self.x_search is None:
            return np.inf
        d = x - self.x_search
        return float(np.sqrt(np.einsum("ij,ij->i", d, d)).max(initial=0.0))

    def covers(self, x: np.ndarray, reach: float) -> bool:
        """True if the candidates hold every pair that can come within ghat while nodes move by at
        most ``reach`` (mm) beyond x."""
        return self.x_search is not None and 2.0 * (self.moved(x) + reach) + self.pair_enf.cutoff < self.search_margin

    def couplings(self, nodes=None) -> np.ndarray:
        """(p, 2) node pairs coupled by stencils ``nodes`` (c, S) (and every node with each
        force-controlled plate)."""
        parts = []
        if nodes is not None and len(nodes):
            S = nodes.shape[1]
            for i in range(S):
                for j in range(i + 1, S):
                    parts.append(nodes[:, [i, j]])
        fc = np.flatnonzero(self.plates.force_controlled) if self.P else np.zeros(0, dtype=np.int64)
        for p in fc:
            parts.append(np.column_stack([np.arange(self.n), np.full(self.n, self.n + p)]))
        if not parts:
            return np.zeros((0, 2), dtype=np.int64)
        c = np.sort(np.vstack(parts), axis=1)
        c = c[c[:, 0] != c[:, 1]]
        return np.unique(c, axis=0)

    # ------------------------------------------------------------------ potentials
    def pairs(self, x: np.ndarray, hessian: bool = True, project: bool = True):
        """Yarn-yarn barrier at x (n, 3): a :class:`~homtex.contact.potential.ContactEval`
        (``project``: each pair's Hessian block projected to PSD, else exact)."""
        return pair_potential(x, self.stencil, self.pair_enf if project else self._exact, hessian=hessian)

    def plate_gaps(self, x: np.ndarray, z: np.ndarray) -> np.ndarray:
        """(n P,) gaps of every node against every plate at plate heights z (P,)."""
        if not self.P:
            return np.zeros(0)
        pn, pi = self.plate_nodes, self.plate_index
        return self.plates.normal[pi] * (x[pn, 2] - z[pi]) - self.node_r[pn]

    def plate_terms(self, x: np.ndarray, z: np.ndarray, hessian: bool = True) -> dict:
        """Yarn-plate barrier at x (n, 3), plate heights z (P,): energy, gradient on the nodes
        (n, 3) and on the plates' heights (P,), 6 x 6 blocks over (node, plate node) of the
        active ones, and the force of the yarns on each plate along z (N, (P,))."""
        gap = self.plate_gaps(x, z)
        out = {"gap": gap, "energy": 0.0, "grad": np.zeros((self.n, 3)), "grad_plate": np.zeros(self.P),
               "active": np.zeros(0, dtype=np.int64), "blocks": np.zeros((0, 6, 6)), "lam": np.zeros(len(gap))}
        if not self.P:
            return out
        act = np.flatnonzero(gap < self.plate_enf.cutoff)
        e, e1, e2 = self.plate_enf.energy(gap[act])
        out["energy"] = float(e.sum())
        out["active"] = act
        if not np.isfinite(out["energy"]):
            return out
        sgn = self.plates.normal[self.plate_index[act]].astype(float)
        np.add.at(out["grad"][:, 2], self.plate_nodes[act], e1 * sgn)
        np.add.at(out["grad_plate"], self.plate_index[act], -e1 * sgn)
        out["lam"][act] = -e1
        if hessian:
            v = np.zeros((len(act), 6))
            v[:, 2] = sgn
            v[:, 5] = -sgn
            out["blocks"] = e2[:, None, None] * v[:, :, None] * v[:, None, :]
        return out

    def plate_block_nodes(self, act: np.ndarray) -> np.ndarray:
        """(len(act), 2) (node, plate node) of plate candidates ``act``."""
        return np.column_stack([self.plate_nodes[act], self.n + self.plate_index[act]])

    # ------------------------------------------------------------------ friction
    def friction_lag(self, x: np.ndarray, z: np.ndarray) -> tuple[FrictionLag | None, FrictionLag | None]:
        """Friction contacts frozen at x (n, 3), plate heights z: (pairs, plates) (None: no friction)."""
        if not self.has_friction:
            return None, None
        pl = None
        fp = None
        if self.stencil is not None and len(self.stencil) and self.mu_pair.max(initial=0.0) > 0:
            fp = pair_friction_lag(x, self.stencil, self.pair_enf, mu=self.mu_pair)
        if self.P and self.mu_plate.max(initial=0.0) > 0:
            pl = plate_friction_lag(x, self.plate_nodes, self.node_r[self.plate_nodes], self.plates.origins(z),
                                    self.plates.normals(), self.plate_enf, plate=self.plate_index,
                                    mu=self.mu_plate[self.plate_nodes])
        return fp, pl
