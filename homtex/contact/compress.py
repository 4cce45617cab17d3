"""Compression test between two rigid plates: ``compress``.

The cell (or frame) lies between a fixed bottom plate and a top plate that moves down
(displacement control) or carries a uniform pressure (force control, as in the paper).
Each step is a linear-beam contact solve whose gaps are linearised about the previous
step's deformed state (contacts are searched again at every step), so new contacts appear
as the fabric compresses while every step stays a convex problem.
"""

from __future__ import annotations

import time

import numpy as np

from ..errors import InputError, SolverError
from ..model.frame import Frame
from .constraints import Plate, node_contact_radius
from .solve import Contact, ContactSolver

ENERGY_NAMES = ("axial", "torsion", "bending_y", "bending_z", "shear")


def _frame_of(obj):
    if isinstance(obj, Frame):
        return obj, None, {}
    fr = getattr(obj, "frame", None)
    if not isinstance(fr, Frame):
        raise InputError(f"compress needs a homtex.Frame or an object with a .frame (a homtex Cell), "
                         f"got {type(obj).__name__}")
    groups = getattr(obj, "groups", None)
    info = getattr(obj, "info", None) or {}
    return fr, groups, info


def _default_fixed(frame, x):
    """Pin the rigid motions that frictionless plates and contacts leave free, per connected part.

    For every connected part (yarn or group of joined yarns): ux, uy of its lowest node; if the
    part is straight, also the spin about its axis (rotation DOF nearest to the axis; exact
    for axis-aligned yarns); if it does not wrap around a period (finite part), the in-plane DOF
    of its node farthest from the lowest one (rotation about z). Frictionless normal contacts
    carry no load along these motions, so the pins' reactions stay zero in a well-posed problem.
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    n = frame.n_nodes
    el = frame.elements
    g = coo_matrix((np.ones(len(el)), (el[:, 0], el[:, 1])), shape=(n, n))
    ncomp, lab = connected_components(g, directed=False)
    elab = lab[el[:, 0]]
    fixed = {}
    e1 = frame.R[:, 0]
    for comp in range(ncomp):
        nodes = np.flatnonzero(lab == comp)
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


def compress(cell_or_frame, *, strain=None, steps: int = 20, control: str = "displacement",
             contact: Contact | None = None, pressure=None, fixed=None, thickness: float | None = None,
             area: float | None = None, solver: str = "direct", tol: float = 1e-10,
             maxiter: int | None = None, max_cuts: int = 4, progress: bool = False, geometry: str = "linear",
             stabilize: float = 0.0):
    """Compression curve of a cell between two rigid frictionless plates.

    Parameters
    ----------
    cell_or_frame : homtex.Frame, or an object with ``.frame`` (a homtex Cell; its ``.groups``
        {name: (m,) bool element mask} give per-group energies, ``.info["thickness"]`` the
        plate distance).
    strain : final compression strain (plate displacement / initial plate distance, > 0), or
        an increasing array of strains (displacement control).
    steps : number of equal steps up to ``strain`` (or ``pressure``).
    control : "displacement" (the top plate moves) or "force" (uniform ``pressure`` on it).
    pressure : final pressure (kPa) or an increasing array (force control).
    contact : Contact options (default ``Contact()``: pdas, augmented Lagrangian).
    fixed : extra supports (dict as in ``solve_static``); default pins the in-plane rigid
        motions that frictionless plates leave free (ux, uy of the lowest node for a 2-periodic
        frame; plus one in-plane DOF against rotation about z for a finite frame).
    thickness : plate distance, mm (default ``info["thickness"]``, else the yarns' extent
        (z_max + r) - (z_min - r)); the bottom plate touches the lowest yarn surface.
    area : nominal area for the stress, mm^2 (default |p1 x p2| of a 2-periodic frame in x-y,
        else the x-y bounding box of the yarns).

    max_cuts : a step whose contact iteration fails (cycling active set, penetration, solver
        failure) is retried as two half steps, recursively up to ``max_cuts`` times (down to
        1/2**max_cuts of the step); only then the curve ends. 0 disables the retries.
    progress : show a progress bar (rich if installed, else lines on stderr).
    geometry : "linear" (small rotations; contact re-linearised per step) or "nonlinear"
        (co-rotational beams, Newton iterations per step: yarns may rotate and buckle; the
        large-compression regime the linear model does not reach).
    stabilize : viscous stabilisation of the nonlinear steps (see
        :func:`homtex.contact.nonlinear.newton_contact`); its largest force is recorded per step.

    Returns
    -------
    xarray.Dataset over ``strain`` (compression positive) with stress (kPa), force (N),
    plate_displacement (mm), active contacts (total, yarn-yarn, yarn-plate), max penetration
    (mm), contact iterations, linear solves, energies (N mm) and, with groups, ``group_energy``.
    A failing step ends the curve: the steps before it are kept and ``attrs["status"]`` says
    why (``"ok"`` otherwise).
    """
    import xarray as xr

    frame, groups, info = _frame_of(cell_or_frame)
    if control not in ("displacement", "force"):
        raise InputError(f"control must be 'displacement' or 'force', got {control!r}")
    contact = Contact() if contact is None else contact
    if not isinstance(contact, Contact):
        raise InputError(f"contact must be a homtex.Contact, got {type(contact).__name__}")
    if int(steps) != steps or steps < 1:
        raise InputError(f"steps must be a positive integer, got {steps!r}")
    if geometry not in ("linear", "nonlinear"):
        raise InputError(f"geometry must be 'linear' or 'nonlinear', got {geometry!r}")
    if not (np.isfinite(stabilize) and 0.0 <= stabilize < 1.0):
        raise InputError(f"stabilize must lie in [0, 1) (fraction of the diagonal stiffness), got {stabilize!r}")
    if frame.dim_periodic == 3:
        raise InputError("compress: a 3-periodic frame has no free surfaces for plates")
    if frame.dim_periodic and np.any(np.abs(frame.periods[:, 2]) > 1e-9 * np.abs(frame.periods).max()):
        raise InputError(f"compress: lattice vectors must lie in the x-y plane (plates are normal to z), "
                         f"got {frame.periods.tolist()}")
    x = frame.nodes
    rn = node_contact_radius(frame)
    z_lo = float((x[:, 2] - rn).min())
    z_hi = float((x[:, 2] + rn).max())
    if thickness is None:
        thickness = info.get("thickness") if isinstance(info, dict) else None
    H0 = float(thickness) if thickness is not None else z_hi - z_lo
    if not H0 > 0:
        raise InputError(f"thickness must be positive, got {thickness!r}")
    area_source = "given"
    if area is None:
        if frame.dim_periodic == 2:
            area = float(np.linalg.norm(np.cross(frame.periods[0], frame.periods[1])))
            area_source = "|p1 x p2| of the periodic cell"
        else:
            ext = (x[:, :2] + rn[:, None]).max(axis=0) - (x[:, :2] - rn[:, None]).min(axis=0)
            area = float(ext[0] * ext[1])
            area_source = "x-y bounding box of the yarns"
    area = float(area)
    if not area > 0:
        raise InputError(f"area must be positive (mm^2), got {area!r}")

    if control == "displacement":
        if strain is None:
            raise InputError("compress: 'strain' (final compression strain) is required for displacement control")
        targets = _targets(strain, steps, "strain")
        if np.any(targets >= 1.0):
            raise InputError(f"strain must stay below 1 (plates would meet), got max {targets.max()}")
    else:
        if pressure is None:
            raise InputError("compress: 'pressure' (kPa) is required for control='force'")
        targets = _targets(pressure, steps, "pressure")
    fix = _default_fixed(frame, x) if fixed is None else dict(fixed)
    if fixed is not None:
        for node, spec in _default_fixed(frame, x).items():
            fix.setdefault(node, spec)
    bottom = Plate(z=z_lo, normal=1, displacement=0.0, name="bottom")
    top = Plate(z=z_lo + H0, normal=-1, displacement=0.0, name="top")
    t0 = time.perf_counter()
    cs = ContactSolver(frame, fix, None, contact, plates=[bottom, top], solver=solver, tol=tol, maxiter=maxiter)
    names = list(groups) if groups else []
    masks = [np.asarray(groups[g], dtype=bool) for g in names]
    for g, mk in zip(names, masks):
        if mk.shape != (frame.n_elements,):
            raise InputError(f"group {g!r}: mask must have shape ({frame.n_elements},), got {mk.shape}")
    rec = {k: [] for k in ("strain", "stress", "force", "plate_displacement", "active_contacts",
                           "active_yarn_yarn", "active_yarn_plate", "max_penetration", "contact_iterations",
                           "linear_solves", "contact_energy", "bottom_force", "pressure", "newton_iterations",
                           "stabilization_force", *ENERGY_NAMES)}
    rec["group_energy"] = []
    status = "ok"
    u_ref = None
    warm = None
    if int(max_cuts) != max_cuts or max_cuts < 0:
        raise InputError(f"max_cuts must be a non-negative integer, got {max_cuts!r}")

    def apply(value):
        if control == "displacement":
            cs.set_plate(1, displacement=-value * H0)
        else:
            cs.set_plate(1, force=value * area * 1e-3)

    cor = None
    plate_u = {"u": None}
    if geometry == "nonlinear":
        from ..analysis.nonlinear import Corotational
        from .newton import newton_contact

        cor = Corotational(frame, cs.assembler)

    def solve_from(u0, w0):
        if cor is None:
            return cs.solve(u_ref=u0, warm_keys=w0)
        # the co-rotational state (cor, plate_u) is the previous converged one; a failed Newton
        # solve restores it, so a halved step starts from there too
        res, pu, _ = newton_contact(cs, cor, plate_u=plate_u["u"], warm_keys=w0, stabilize=stabilize)
        plate_u["u"] = pu
        return res

    def advance(a, b, u0, w0, cuts):
        """Solve at load level b from the converged state at a; halve the step on failure.
        Returns (result, number of sub-steps used); raises the first failure's error."""
        apply(b)
        try:
            return solve_from(u0, w0), 1
        except (SolverError, np.linalg.LinAlgError) as err:
            if cuts == 0 or "singular" in str(err):   # a singular operator does not improve
                raise
            first_error = err
        mid = 0.5 * (a + b)
        try:
            r1, n1 = advance(a, mid, u0, w0, cuts - 1)
            r2, n2 = advance(mid, b, r1.extra["u_ext"], r1.extra["active_keys"], cuts - 1)
        except (SolverError, np.linalg.LinAlgError):
            raise first_error from None
        return r2, n1 + n2

    rec["substeps"] = []
    previous = 0.0
    from ..output.progress import Progress

    bar = Progress(len(targets), "compression steps", enabled=progress)
    for step, target in enumerate(targets, start=1):
        try:
            res, nsub = advance(previous, target, u_ref, warm, int(max_cuts))
        except (SolverError, np.linalg.LinAlgError, RuntimeError) as err:
            label = f"strain {target:.4g}" if control == "displacement" else f"pressure {target:.4g} kPa"
            halved = "" if max_cuts == 0 or "singular" in str(err) else \
                f" (also after halving the step {int(max_cuts)} times)"
            status = f"failed at step {step} ({label}){halved}: {err}"
            break
        e = res.extra
        if not all(np.isfinite(v).all() for v in (res.u, e["plate_force"])):
            status = f"failed at step {step}: non-finite result"
            break
        u_ref = e["u_ext"]
        warm = e["active_keys"]
        previous = target
        rec["substeps"].append(nsub)
        bar.step(f"{nsub} sub-steps" if nsub > 1 else "")
        w = float(e["plate_displacement"][1])
        F = float(e["plate_force"][1])
        c = res.contacts
        rec["strain"].append(-w / H0)
        rec["plate_displacement"].append(-w)
        rec["force"].append(F)
        rec["stress"].append(F / area * 1e3)
        rec["pressure"].append(target if control == "force" else F / area * 1e3)
        rec["bottom_force"].append(float(e["plate_force"][0]))
        rec["active_contacts"].append(c.n_active)
        rec["active_yarn_yarn"].append(c.n_yarn)
        rec["active_yarn_plate"].append(c.n_plate)
        rec["max_penetration"].append(e["max_penetration"])
        rec["contact_iterations"].append(e["contact_iterations"])
        rec["linear_solves"].append(e["linear"]["linear_solves"])
        rec["contact_energy"].append(e["contact_energy"])
        rec["newton_iterations"].append(int(e.get("newton_iterations", 0)))
        rec["stabilization_force"].append(float(e.get("stabilization_force", 0.0)))
        tot = np.zeros(frame.n_elements)
        for k in ENERGY_NAMES:
            rec[k].append(float(res.energy[k].sum()))
            tot += res.energy[k]
        rec["group_energy"].append([float(tot[mk].sum()) for mk in masks])
    bar.close()
    seconds = time.perf_counter() - t0
    ds = _dataset(xr, rec, names, status, dict(
        control=control, thickness_mm=H0, area_mm2=area, area_source=area_source,
        strategy=contact.strategy, enforcement=contact.enforcement, penalty_N_per_mm=cs.k,
        bottom_plate_z_mm=z_lo, top_plate_z_mm=z_lo + H0, solver=solver, seconds=seconds, geometry=geometry,
        supports=str(fix), steps_requested=int(len(targets)), stabilize=float(stabilize), initial_overlap=contact.initial_overlap,
        initial_overlaps=int(cs.initial_overlaps), initial_overlap_max_mm=cs.initial_overlap_max))
    if control == "displacement":
        flag_force_drops(ds, what="compress")
    return ds


def flag_force_drops(ds, *, rel: float = 0.02, what: str = "curve"):
    """Mark a displacement-controlled curve whose force falls on the way (in place; returns ds).

    A drop of more than ``rel`` x the force reached so far is either a snap-through (physical:
    a yarn buckles or slips past another) or an artefact of a load step too large for the
    per-step re-linearised contact; the two differ in that the artefact moves with the step
    count. ``attrs``: ``force_drop_max`` (largest drop / force reached, 0 for a monotone curve),
    ``force_drop_strain`` (where it ends, NaN if none) and, above ``rel``, ``check`` (message,
    also warned).
    """
    import warnings

    f = np.asarray(ds["force"].values, dtype=float)
    e = np.asarray(ds["strain"].values, dtype=float)
    ds.attrs["force_drop_max"] = 0.0
    ds.attrs["force_drop_strain"] = float("nan")
    if len(f) < 2 or not np.all(np.isfinite(f)):
        return ds
    top = np.maximum.accumulate(f)
    drop = np.where(top > 0, (top - f) / np.where(top > 0, top, 1.0), 0.0)
    k = int(np.argmax(drop))
    ds.attrs["force_drop_max"] = float(drop[k])
    if drop[k] > rel:
        ds.attrs["force_drop_strain"] = float(e[k])
        msg = (f"{what}: the force falls by {100 * drop[k]:.1f} % of the force reached, ending at strain "
               f"{e[k]:.4g} (step {k + 1} of {len(f)}): a snap-through or a load step too large for the "
               "re-linearised contact; run it again with twice the steps - an artefact moves, a snap stays")
        ds.attrs["check"] = msg
        warnings.warn(msg, UserWarning, stacklevel=3)
    return ds


def _targets(v, steps, name):
    arr = np.atleast_1d(np.asarray(v, dtype=float))
    if arr.size == 1:
        if not (np.isfinite(arr[0]) and arr[0] > 0):
            raise InputError(f"{name} must be positive, got {v!r}")
        return arr[0] * np.arange(1, int(steps) + 1) / int(steps)
    if not (np.all(np.isfinite(arr)) and np.all(arr > 0) and np.all(np.diff(arr) > 0)):
        raise InputError(f"{name} values must be positive and increasing")
    return arr


def _dataset(xr, rec, groups, status, attrs):
    meta = {
        "stress": ("kPa", "nominal compressive stress (top plate force / area)"),
        "force": ("N", "compressive force on the top plate"),
        "plate_displacement": ("mm", "downward displacement of the top plate"),
        "pressure": ("kPa", "applied pressure (force control) or measured stress"),
        "bottom_force": ("N", "compressive force on the bottom plate"),
        "active_contacts": ("1", "active contacts (yarn-yarn + yarn-plate)"),
        "active_yarn_yarn": ("1", "active yarn-yarn contacts"),
        "active_yarn_plate": ("1", "active yarn-plate contacts"),
        "max_penetration": ("mm", "largest overlap of the linearised contact gaps"),
        "contact_iterations": ("1", "active-set iterations of the step (last sub-step)"),
        "linear_solves": ("1", "linear solves of the step (last sub-step)"),
        "substeps": ("1", "sub-steps the step needed (1: none; more after halving a failed step)"),
        "contact_energy": ("N mm", "energy stored in the contact penalty springs"),
        "newton_iterations": ("1", "Newton iterations of the step (geometry='nonlinear'; 0: linear)"),
        "stabilization_force": ("N", "largest viscous stabilisation force on a node (geometry='nonlinear')"),
        "axial": ("N mm", "axial strain energy"),
        "torsion": ("N mm", "torsional strain energy"),
        "bending_y": ("N mm", "bending strain energy about local y"),
        "bending_z": ("N mm", "bending strain energy about local z"),
        "shear": ("N mm", "shear strain energy"),
    }
    strain = np.asarray(rec["strain"], dtype=float)
    data = {}
    for k, (unit, ln) in meta.items():
        data[k] = xr.DataArray(np.asarray(rec[k]), dims=("strain",), attrs={"units": unit, "long_name": ln})
    if groups:
        ge = np.asarray(rec["group_energy"], dtype=float).reshape(len(strain), len(groups))
        data["group_energy"] = xr.DataArray(ge, dims=("strain", "group"),
                                            attrs={"units": "N mm", "long_name": "strain energy per element group"})
    coords = {"strain": ("strain", strain, {"units": "1", "long_name": "compression strain (plate displacement / initial plate distance)"})}
    if groups:
        coords["group"] = ("group", np.array(groups, dtype=str), {"units": "1", "long_name": "element group"})
    ds = xr.Dataset(data, coords=coords)
    ds.attrs.update({k: v for k, v in attrs.items()})
    ds.attrs["status"] = status
    ds.attrs["steps_done"] = int(len(strain))
    return ds
