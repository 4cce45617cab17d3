"""The scene of a solve: supports, loads, rigid plates and pins, described once.

``fixed``: dict node -> "all" | list of DOF indices 0..5 (held at zero) |
dict {DOF index: prescribed value}. ``loads``: dict node -> 6 numbers
(Fx, Fy, Fz, Mx, My, Mz) in N and N mm. Plates are rigid planes normal to z that the
yarns cannot cross (:class:`Plate`). :class:`Scene` bundles them for one frame and is what
every solve consumes; :func:`default_pins` and :func:`periodic_pins` are the two ways homtex
removes the rigid motions that nothing else holds.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from ..errors import InputError
from ..validate import check_number
from .arrays import MAX_COORD, as_real
from .topology import check_held, components

__all__ = ["DOF_NAMES", "Plate", "Scene", "default_pins", "parse_fixed", "parse_loads", "periodic_pins"]

DOF_NAMES = ("ux", "uy", "uz", "rx", "ry", "rz")


def _node_index(node, n, what):
    try:
        if isinstance(node, (bool, np.bool_, str, bytes)):
            raise TypeError
        i = int(node)
    except (TypeError, ValueError, OverflowError):
        raise InputError(f"{what}: node {node!r} is not an integer index") from None
    if i != node or not (0 <= i < n):
        raise InputError(f"{what}: node {node!r} is outside 0..{n - 1}")
    return i


def _dof_index(node, dof):
    try:
        if isinstance(dof, (bool, np.bool_, str, bytes)):
            raise TypeError
        d = int(dof)
    except (TypeError, ValueError, OverflowError):
        raise InputError(f"node {node}: DOF {dof!r} is not an integer 0..5") from None
    if d != dof or not (0 <= d <= 5):
        raise InputError(f"node {node}: DOF {dof!r} is not in 0..5 ({', '.join(DOF_NAMES)})")
    return d


def parse_fixed(fixed, n_nodes: int):
    """(mask, values): (6n,) bool constrained DOFs and (6n,) prescribed values."""
    mask = np.zeros(6 * n_nodes, dtype=bool)
    vals = np.zeros(6 * n_nodes)
    if fixed is None:
        return mask, vals
    if not isinstance(fixed, Mapping):
        raise InputError("fixed must be a dict node -> 'all' | [dofs] | {dof: value}")
    for node, spec in fixed.items():
        i = _node_index(node, n_nodes, "fixed")
        if isinstance(spec, str):
            if spec != "all":
                raise InputError(f"fixed[{node}]: unknown support {spec!r} (use 'all', a DOF list or a dict)")
            mask[6 * i:6 * i + 6] = True
        elif isinstance(spec, Mapping):
            for dof, v in spec.items():
                d = _dof_index(node, dof)
                v = float(as_real(v, f"fixed[{node}][{dof}] (prescribed value)", ndim=0, limit=MAX_COORD))
                mask[6 * i + d] = True
                vals[6 * i + d] = v
        else:
            dofs = spec if isinstance(spec, (list, tuple, np.ndarray)) else [spec]
            for dof in (dofs.tolist() if isinstance(dofs, np.ndarray) else dofs):
                mask[6 * i + _dof_index(node, dof)] = True
    return mask, vals


def parse_loads(loads, n_nodes: int) -> np.ndarray:
    """(6n,) load vector from dict node -> (Fx, Fy, Fz, Mx, My, Mz)."""
    f = np.zeros(6 * n_nodes)
    if loads is None:
        return f
    if not isinstance(loads, Mapping):
        raise InputError("loads must be a dict node -> 6 numbers (Fx, Fy, Fz, Mx, My, Mz)")
    for node, v in loads.items():
        i = _node_index(node, n_nodes, "loads")
        v = as_real(v, f"loads[{node}]").ravel()
        if v.shape != (6,):
            raise InputError(f"loads[{node}] must have 6 numbers (Fx, Fy, Fz, Mx, My, Mz), got {v.size}")
        f[6 * i:6 * i + 6] += v
    return f




@dataclass
class Plate:
    """A rigid, frictionless plane z = ``z`` (mm) that the yarns cannot cross.

    Parameters
    ----------
    z : height of the plane, mm.
    normal : +1 when the yarns lie above the plate (a bottom plate), -1 when below (a top plate).
    displacement : prescribed motion of the plate along z, mm (default 0: fixed).
    force : force (N) pressing the plate against the yarns (force control; its
        motion is then an unknown).
    pressure, area : alternatively a pressure (kPa) on an area (mm^2): force = pressure * area * 1e-3.
    """

    z: float
    normal: int = 1
    displacement: float | None = None
    force: float | None = None
    pressure: float | None = None
    area: float | None = None
    name: str = ""

    def __post_init__(self):
        self._assign(_plate_state(vars(self)))

    def __setattr__(self, name, value):
        """Before ``__post_init__`` the dataclass fills the fields; after it, every assignment is
        checked like the constructor's arguments, with the other fields (``p.force = 5`` on a
        displacement-controlled plate, ``p.z = nan`` raise InputError). ``p.pressure`` or
        ``p.area`` recompute the force; ``p.force`` replaces a pressure given before."""
        if "_checked" not in self.__dict__:
            object.__setattr__(self, name, value)
            return
        if name not in _PLATE_FIELDS:
            raise InputError(f"Plate has no attribute {name!r}; its fields are {list(_PLATE_FIELDS)}")
        state = {k: getattr(self, k) for k in _PLATE_FIELDS}
        state[name] = value
        if name == "force" and value is not None:
            state["pressure"] = state["area"] = None      # a force given directly replaces the pressure
        elif name in ("pressure", "area") and state["pressure"] is not None:
            state["force"] = None                         # recomputed from pressure x area
        self._assign(_plate_state(state))

    def __delattr__(self, name):
        raise InputError(f"Plate fields cannot be deleted ({name!r}); set a value (or None) instead")

    def _assign(self, state: dict) -> None:
        for k, v in state.items():
            object.__setattr__(self, k, v)
        object.__setattr__(self, "_checked", True)

    @property
    def force_controlled(self) -> bool:
        return self.force is not None


_PLATE_FIELDS = ("z", "normal", "displacement", "force", "pressure", "area", "name")


def _plate_state(d: dict) -> dict:
    """The checked fields of a Plate from ``d`` (InputError naming the field), force derived from
    pressure x area where a pressure is given."""
    st = {k: d[k] for k in _PLATE_FIELDS}
    normal = st["normal"]
    if isinstance(normal, (bool, np.bool_)) or not isinstance(normal, (int, float, np.integer, np.floating)) \
            or normal not in (1, -1):
        raise InputError(f"Plate.normal must be +1 (yarns above) or -1 (yarns below), got {normal!r}")
    st["normal"] = int(normal)
    st["z"] = check_number(st["z"], "Plate.z (mm)", ge=-MAX_COORD, le=MAX_COORD)
    if st["area"] is not None and st["pressure"] is None:
        raise InputError("Plate.area (mm^2) goes with Plate.pressure; give force (N) alone otherwise")
    if st["pressure"] is not None:
        if st["force"] is not None:
            raise InputError("Plate: give either 'force' or 'pressure' (with 'area'), not both")
        st["pressure"] = check_number(st["pressure"], "Plate.pressure (kPa)")
        if st["area"] is None:
            raise InputError("Plate.pressure needs a positive 'area' (mm^2)")
        st["area"] = check_number(st["area"], "Plate.area (mm^2)", gt=0.0)
        st["force"] = st["pressure"] * st["area"] * 1e-3
    if st["force"] is not None and st["displacement"] is not None:
        raise InputError("Plate: give either 'displacement' (displacement control) or 'force' "
                         "(force control), not both; set the other to None first")
    if st["displacement"] is not None:
        st["displacement"] = check_number(st["displacement"], "Plate.displacement (mm)", ge=-MAX_COORD,
                                          le=MAX_COORD)
    if st["force"] is not None:
        st["force"] = check_number(st["force"], "Plate.force (N)", ge=-1e12, le=1e12)
    if not isinstance(st["name"], str):
        raise InputError(f"Plate.name must be a string, got {st['name']!r}")
    return st


@dataclass
class Scene:
    """Supports, loads and plates of one frame.

    Attributes
    ----------
    frame : the Frame.
    mask : (6n,) bool, DOFs held by supports; values : (6n,) their prescribed values (mm, rad).
    loads : (6n,) applied nodal loads (N, N mm), pre-strain loads not included.
    plates : rigid plates (each an extra node n + p of the contact solve whose only free DOF,
        under force control, is uz).
    fixed : the supports as given (dict), for reports.
    """

    frame: object
    mask: np.ndarray
    values: np.ndarray
    loads: np.ndarray
    plates: list = field(default_factory=list)
    fixed: dict = field(default_factory=dict)

    @classmethod
    def build(cls, frame, fixed=None, loads=None, plates=()) -> "Scene":
        """Parse supports, loads and plates for ``frame`` (InputError names the culprit)."""
        n = frame.n_nodes
        mask, values = parse_fixed(fixed, n)
        plates = list(plates or [])
        for i, p in enumerate(plates):
            if not isinstance(p, Plate):
                raise InputError(f"plates[{i}] must be a homtex.Plate, got {type(p).__name__}")
        return cls(frame=frame, mask=mask, values=values, loads=parse_loads(loads, n), plates=plates,
                   fixed=dict(fixed or {}))

    def check_held(self, extra_edges=None, extra_images=None, mask=None) -> None:
        """SolverError naming every part that the supports (and ``extra_edges``) do not hold."""
        check_held(self.frame, self.mask if mask is None else mask, extra_edges, extra_images)


def default_pins(frame, x=None) -> dict:
    """Pin the rigid motions that frictionless plates and contacts leave free, per connected part.

    For every connected part (yarn or group of joined yarns): ux, uy of its lowest node; if the
    part is straight, also the spin about its axis (rotation DOF nearest to the axis; exact
    for axis-aligned yarns); if it does not wrap around a period (finite part), the in-plane DOF
    of its node farthest from the lowest one (rotation about z). Frictionless normal contacts
    carry no load along these motions, so the pins' reactions stay zero in a well-posed problem.
    ``x`` (n, 3): node positions to judge "lowest" and "farthest" (default the frame's nodes).
    Returns a ``fixed`` dict.
    """
    x = frame.nodes if x is None else x
    n = frame.n_nodes
    el = frame.elements
    g = coo_matrix((np.ones(len(el)), (el[:, 0], el[:, 1])), shape=(n, n))
    ncomp, label = connected_components(g, directed=False)
    elab = label[el[:, 0]]
    fixed = {}
    e1 = frame.R[:, 0]
    for comp in range(ncomp):
        nodes = np.flatnonzero(label == comp)
        a = int(nodes[np.argmin(x[nodes, 2])])
        dofs = [0, 1]
        ec = np.flatnonzero(elab == comp)
        if len(ec):
            ax = e1[ec[0]]
            if np.all(np.linalg.norm(np.cross(e1[ec], ax), axis=1) < 1e-9):
                dofs.append(3 + int(np.argmax(np.abs(ax))))
        fixed[a] = dofs
        wraps = frame.dim_periodic and len(ec) and np.any(frame.images[ec] != 0)
        if not wraps and len(nodes) > 1:
            dxy = x[nodes, :2] - x[a, :2]
            q = int(np.argmax(np.einsum("ij,ij->i", dxy, dxy)))
            b = int(nodes[q])
            if b != a and np.linalg.norm(dxy[q]) > 0:
                fixed[b] = [1] if abs(dxy[q, 0]) >= abs(dxy[q, 1]) else [0]
    return fixed


def periodic_pins(frame) -> np.ndarray:
    """(6n,) bool mask pinning the translations of one node per connected part of a periodic
    frame (and, for k = 1 along a coordinate axis, the rotation about that axis): what
    periodic fluctuations leave free. SolverError if a part is still free."""
    n = frame.n_nodes
    label, _ = components(n, frame.elements, frame.images)
    _, first = np.unique(label, return_index=True)
    mask = np.zeros((n, 6), dtype=bool)
    mask[first, :3] = True
    if frame.dim_periodic == 1:
        t = np.abs(frame.periods[0]) / np.linalg.norm(frame.periods[0])
        ax = int(np.argmax(t))
        if t[ax] > 1 - 1e-12:
            mask[first, 3 + ax] = True
    mask = mask.ravel()
    check_held(frame, mask)
    return mask
