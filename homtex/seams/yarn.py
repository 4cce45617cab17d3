"""Seamed spacer fabric: cushion profile between lock-stitch seams (``seam_profile``).

Two models:

``method="yarn"`` (default, :func:`yarn_profile`): the yarn-level seam cell of
    :mod:`homtex.geometry.seam` (the fabric cell tiled over one seam distance and one stitch
    length, a lock stitch 301 with axial pre-strain eps0 on every stitch element) solved with
    yarn-yarn contact while eps0 is ramped up; the profile h(x) is measured on the outer yarn
    surfaces. studies/calibrate_seam.py tries to calibrate eps0 once on d = 24 mm (then 18 and
    43 mm would be predictions with nothing changed).
    Limits (measured, studies/calibrate_seam.py): with geometrically linear beams the seam dip is
    local (a few mm wide) and the cushion maximum stays at or slightly above the thickness for
    every eps0, so the paper's 14.33 mm at d = 24 mm cannot be reached by eps0 alone: the cell
    file's ``prestrain`` is a nominal, UNCALIBRATED value. The contact active set (pdas) can cycle
    at some load steps; failed steps are halved, and the result depends slightly on the step path
    (contact geometry re-linearised per step). ``geometry="nonlinear"`` (co-rotational beams)
    leaves the dip as it is where its ramp gets (studies/nonlinear_spacer.py).
``method="foundation"`` (:func:`foundation_profile`): the analytical model below. Protocol:
    eps0 = 0.40, the sewing machine's needle-thread tension of the paper's Table 1 read as the
    stitch pre-strain (an assumption, not fitted), and the layer rigidity calibrated ONCE on
    d = 24 mm (14.33 mm, :func:`calibrate_layer_rigidity`); 18 and 43 mm are then predictions
    (12.23 and 20.05 mm against the paper's 10.23 / 20.3 and the measured 8-12 / 20 mm). The
    calibrated rigidity (230 N mm^2 per stitch) is 56x the sum of the layer yarns' own and 150x
    what the yarn-level cell shows (studies/seam_length_scale.py): the model says what the
    layer would have to be, not what the yarns give.

Foundation model (a documented simplification, not a yarn-level seam solve)
----------------------------------------------------------------------------
A seam cell spans one seam distance d across the seam (x) and one stitch length s
along it (y). Each surface layer is an Euler-Bernoulli strip of bending rigidity D
(N mm^2 per stitch length, from the layer's yarns) resting on the pile, a linear
Winkler foundation of stiffness k = 2 E_c s / H (N/mm per mm of x; E_c the fabric's
compression modulus from the unseamed yarn-level cell, H its thickness: a layer that moves by w
towards the mid-plane while the other layer moves by w too compresses the pile by 2 w, a strain
2 w / H). Both layers
are pulled towards the mid-plane by the stitch: one point force P per stitch and layer,
repeated every d (periodic). The layer deflection is the periodic Green's function of a
beam on an elastic foundation,

    w(x) = P beta / (2 k) * sum_n exp(-beta |x - n d|) (cos beta |x - n d| + sin beta |x - n d|),
    beta = (k / (4 D))**(1/4),

and the cushion height is h(x) = H - 2 w(x). The stitch (lock stitch 301: a needle
thread over the top layer, a bobbin thread under the bottom layer, interlocked in the
middle) has, per stitch, length L(h_s) = 2 s + 2 h_s (one length s on each face, two
vertical passes of half the local height h_s each way) and wants to be shorter by the
pre-strain eps0: rest length (1 - eps0) L(H). Its tension N = EA (L / L_rest - 1) >= 0
acts through two thread legs on each layer, P = 2 N. The seam-line height h_s solves
H - h_s = 2 P(h_s) w1(0) (w1: deflection per unit force), a scalar monotone equation.

Limits: the foundation is linear (compression at the seam line is far beyond the
fabric's ~30 % linear range), friction and the yarn-level stitch geometry are not
resolved. The layer rigidity is calibrated once on d = 24 mm at the stored eps0
(:func:`calibrate_layer_rigidity`) and stored as ``[parameters.seam] layer_rigidity``.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import InputError

GEOMETRIES = ("linear", "nonlinear")

SLACK_LONG_NAME = "punch travel at the seam line until the stitch thread is slack (tension / stiffness)"

#: default contact options used to measure the fabric modulus for the foundation
_N_IMAGES = 30


def _cell_seam_table(cell) -> dict:
    seam = (cell.parameters or {}).get("seam")
    if not isinstance(seam, dict):
        raise InputError(f"cell {getattr(cell, 'name', '?')!r}: no [parameters.seam] table "
                         "(stitch_length, prestrain, yarn)")
    return seam


def fabric_modulus(cell, *, strain: float = 0.05, steps: int = 2) -> float:
    """Compression modulus E_c (MPa) of the unseamed cell: secant stress / strain at ``strain``.

    Uses ``homtex.compress`` (yarn level, penalty contact); cached on the cell's info.
    """
    info = cell.info
    key = ("fabric_modulus", float(strain))
    if key in info:
        return info[key]
    from ..contact import Contact, compress
    ds = compress(cell, strain=strain, steps=steps, contact=Contact(enforcement="penalty", penalty=5000.0))
    if ds.attrs["status"] != "ok":
        raise InputError(f"fabric_modulus: compression of cell {cell.name!r} failed: {ds.attrs['status']}")
    Ec = float(ds.stress.values[-1] * 1e-3 / ds.strain.values[-1])
    info[key] = Ec
    return Ec


def layer_rigidity(cell, stitch_length: float) -> float:
    """Bending rigidity (N mm^2) of one surface layer over one stitch length, bending across the seam.

    The yarns that run across the wales (x) in a layer are the inlays and the underlaps of the
    pillar stitches: one of each per course and wale system; each bends about its minor axis
    (E pi a b^3 / 4, times the yarn type's ``bending_factor``). D = s / course_spacing * sum over
    the layer's ground and inlay bars.
    """
    info = cell.info
    cs = info["course_spacing"]
    D = 0.0
    for b in info["bars"].values():
        if b.bed != "front":
            continue
        y = cell.yarns[b.yarn]
        a, bb = y.a, y.b
        D += y.E * y.bending_factor * math.pi * max(a, bb) * min(a, bb) ** 3 / 4.0
    return D * stitch_length / cs


def calibrate_layer_rigidity(cell, *, seam_distance: float = 24.0, cushion_height: float = 14.33,
                             prestrain: float | None = None, bounds=(1.0, 1e5)) -> float:
    """Layer rigidity D (N mm^2 per stitch length) of the foundation model that gives
    ``cushion_height`` (mm) at ``seam_distance`` (mm) with the pre-strain ``prestrain`` (None: the
    cell's ``[parameters.seam] foundation_prestrain``). The cushion height falls monotonically
    with D (a stiffer layer spreads the stitch pull over the cushion); InputError if the target is
    not reachable within ``bounds``."""
    from scipy.optimize import brentq

    def resid(logD):
        c = cell.replace(**{"parameters.seam.layer_rigidity": float(np.exp(logD))})
        p = foundation_profile(c, seam_distance=seam_distance, prestrain=prestrain, points=61)
        return float(p.cushion_height) - float(cushion_height)

    lo, hi = np.log(bounds[0]), np.log(bounds[1])
    r_lo, r_hi = resid(lo), resid(hi)
    if r_lo * r_hi > 0:
        raise InputError(f"calibrate_layer_rigidity: cushion height {cushion_height:g} mm at seam_distance "
                         f"{seam_distance:g} mm is not reachable with D in {bounds} N mm^2 (cushion "
                         f"{r_lo + cushion_height:.3g} .. {r_hi + cushion_height:.3g} mm)")
    return float(np.exp(brentq(resid, lo, hi, xtol=1e-10)))


def stitch_pull(hs: float, *, s: float, H: float, eps0: float, EA: float) -> float:
    """Pull P (N) of a sliding lock-stitch thread on each layer, per stitch, at seam-line height
    hs (mm): thread length 2 s + 2 hs, rest length (1 - eps0)(2 s + 2 H), tension-only, two legs
    per layer (module docstring)."""
    L_rest = (1.0 - eps0) * (2 * s + 2 * H)
    return max(0.0, 2.0 * EA * ((2 * s + 2 * hs) / L_rest - 1.0))


def _green(x: np.ndarray, d: float, beta: float, k: float) -> np.ndarray:
    """Periodic deflection per unit point force (mm/N) at x, forces at n d."""
    out = np.zeros_like(x, dtype=float)
    for n in range(-_N_IMAGES, _N_IMAGES + 1):
        r = np.abs(x - n * d) * beta
        out += np.exp(-r) * (np.cos(r) + np.sin(r))
    return out * beta / (2.0 * k)


def foundation_profile(cell, *, seam_distance: float, prestrain: float | None = None, points: int = 121,
                       exact_wales: bool = False):
    """Cushion profile from the ANALYTICAL foundation model (``seam_profile(method="foundation")``).

    ``[parameters.seam] foundation_prestrain`` is the machine's needle-thread tension read as a
    pre-strain (assumption) and ``layer_rigidity`` is calibrated once on d = 24 mm (module
    docstring); other seam distances are predictions.

    Parameters
    ----------
    cell : a spacer Cell (``cells/spacer_20mm.toml``) with a [parameters.seam] table and a
        ``stitch`` yarn type.
    seam_distance : d, mm (> 0): distance between neighbouring seams.
    prestrain : stitch-yarn pre-strain eps0 (0 <= eps0 < 1); None: this model's
        ``[parameters.seam] foundation_prestrain``.
    points : samples of x over one seam distance.
    exact_wales : require d to be a whole number of wale spacings (as a yarn-level seam cell
        needs); InputError otherwise.

    Returns
    -------
    xarray.Dataset: ``height`` (mm) over ``x`` (mm, 0 = seam line, across the seam, (points,)),
    scalar ``cushion_height`` (mm, max height), ``seam_height`` (mm), ``stitch_force`` (N per
    stitch and layer), ``prestrain``; attrs: model, foundation modulus, rigidity.
    """
    import xarray as xr
    from scipy.optimize import brentq

    seam = _cell_seam_table(cell)
    try:
        d = float(seam_distance)
    except (TypeError, ValueError):
        raise InputError(f"seam_distance must be a number (mm), got {seam_distance!r}") from None
    if not (math.isfinite(d) and d > 0):
        raise InputError(f"seam_distance must be positive (mm), got {seam_distance!r}")
    w = cell.info["wale_spacing"]
    if exact_wales and abs(d / w - round(d / w)) > 1e-6:
        raise InputError(f"seam_distance {d:g} mm is not a multiple of the wale spacing {w:.6g} mm "
                         f"({d / w:.4g} wales); a seam cell needs a whole number of wales "
                         f"(e.g. {round(d / w) * w:.6g} mm)")
    eps0 = float(seam.get("foundation_prestrain", 0.0)) if prestrain is None else float(prestrain)
    if not (0.0 <= eps0 < 1.0):
        raise InputError(f"prestrain must lie in [0, 1), got {prestrain!r}")
    s = float(seam.get("stitch_length", 4.0))
    yname = seam.get("yarn", "stitch")
    if yname not in cell.yarns:
        raise InputError(f"[parameters.seam] yarn {yname!r} is not a yarn of the cell (known: {sorted(cell.yarns)})")
    ys = cell.yarns[yname]
    EA = ys.E * math.pi * ys.a * ys.b
    H = float(cell.info["thickness"])
    Ec = fabric_modulus(cell)
    k = 2.0 * Ec * s / H     # both layers move by w: pile strain 2 w / H
    D = float(seam["layer_rigidity"]) if "layer_rigidity" in seam else layer_rigidity(cell, s)
    beta = (k / (4.0 * D)) ** 0.25
    g0 = float(_green(np.array([0.0]), d, beta, k)[0])
    L_rest = (1.0 - eps0) * (2 * s + 2 * H)

    def force(hs):
        return stitch_pull(hs, s=s, H=H, eps0=eps0, EA=EA)

    def resid(hs):
        return (H - hs) - 2.0 * force(hs) * g0

    if resid(H) >= 0.0:
        hs = H
    elif resid(0.0) < 0.0:
        raise InputError(f"prestrain {eps0:g}: the stitch (rest length {L_rest:.4g} mm per stitch) pulls the "
                         f"layers fully together at seam_distance {d:g} mm; the linear-foundation seam model "
                         f"has no solution")
    else:
        hs = brentq(resid, 0.0, H, xtol=1e-12)
    P = force(hs)
    # the punch pushing the top layer down by delta at the seam line shortens the thread path by
    # 2 delta (two vertical passes) and lowers its tension N = P / 2 by EA 2 delta / L_rest
    slack = 0.5 * P * L_rest / (2.0 * EA)
    x = np.linspace(-0.5 * d, 0.5 * d, int(points))
    h = H - 2.0 * P * _green(x, d, beta, k)
    ds = xr.Dataset(
        {"height": ("x", h, {"units": "mm", "long_name": "fabric (cushion) height"}),
         "cushion_height": ((), float(h.max()), {"units": "mm", "long_name": "cushion height (max height between seams)"}),
         "seam_height": ((), float(hs), {"units": "mm", "long_name": "height at the seam line"}),
         "stitch_force": ((), float(P), {"units": "N", "long_name": "stitch pull per stitch and layer"}),
         "slack_travel": ((), float(slack), {"units": "mm", "long_name": SLACK_LONG_NAME}),
         "prestrain": ((), eps0, {"units": "1", "long_name": "stitch-yarn pre-strain eps0"})},
        coords={"x": ("x", x, {"units": "mm", "long_name": "position across the seam (0 = seam line)"})})
    ds.attrs.update(model="foundation", method="foundation",
                    description="surface layers as beams on a linear Winkler foundation (pile), periodic stitch "
                    "forces; eps0 = the machine's needle-thread tension (assumption), layer rigidity "
                    "calibrated once on d = 24 mm",
                    validity="cushion heights: calibrated at d = 24 mm (14.33 mm), other d are predictions of "
                    "this model; eps0 = 0.40 is the paper's machine setting read as a strain (README 'Seams')",
                    status="ok", effective_seam_distance_mm=d,
                    seam_distance_mm=d, stitch_length_mm=s, thickness_mm=H, foundation_modulus_MPa=Ec,
                    layer_rigidity_Nmm2=D, beta_per_mm=beta, stitch_EA_N=EA)
    return ds


def compression_summary(curve, *, validity: float = 0.30) -> dict:
    """Modulus and DIN EN ISO 3386-1 style stresses from a ``compress`` Dataset.

    Returns {"modulus_kPa": slope of a line fit over the curve up to ``validity``,
    "stress_10_kPa", "stress_25_kPa", "stress_40_kPa": interpolated stresses (NaN where
    the curve does not reach), "beyond_validity": list of the levels above ``validity``
    (the linear small-rotation model is valid to about 30 % compression)}.
    """
    e = np.asarray(curve.strain.values, float)
    s = np.asarray(curve.stress.values, float)
    sel = e <= validity + 1e-12
    mod = float(np.polyfit(np.r_[0.0, e[sel]], np.r_[0.0, s[sel]], 1)[0]) if sel.sum() >= 1 else float("nan")
    out = {"modulus_kPa": mod, "beyond_validity": []}
    for lvl in (0.10, 0.25, 0.40):
        v = float(np.interp(lvl, np.r_[0.0, e], np.r_[0.0, s])) if lvl <= e.max() + 1e-12 else float("nan")
        out[f"stress_{int(round(lvl * 100))}_kPa"] = v
        if lvl > validity:
            out["beyond_validity"].append(lvl)
    return out


# ======================================================================================
# yarn-level seam (method="yarn")
# ======================================================================================
#: contact options of the seam solves: pdas + augmented Lagrangian (exact gaps)
def _default_contact():
    from ..contact import Contact

    return Contact()


def _surface_nodes(frame, info):
    """Top- and bottom-layer node indices of the fabric and their outer radius (mm), (n,) arrays."""
    layer = np.asarray(info["layer"])
    n = frame.n_nodes
    r = np.zeros(n)
    out = {}
    for lay in ("top", "bottom"):
        el = frame.elements[layer == lay]
        rc = frame.contact_radius[layer == lay]
        np.maximum.at(r, el[:, 0], rc)
        np.maximum.at(r, el[:, 1], rc)
        out[lay] = np.unique(el.ravel())
    return out["top"], out["bottom"], r


def measure_profile(frame, info, u=None):
    """Cushion profile h(x) of a seam cell (mm): per x bin (one wale wide, centred on the wale
    centres, bin 0 on the seam line) the distance between the outermost top-layer yarn surface
    (max z + r) and the outermost bottom-layer yarn surface (min z - r); stitch yarn excluded.

    Returns (x (2 n_x w,) bin centres relative to the seam line in [-d/2, d/2), mm; h (same), mm).
    """
    x = frame.nodes if u is None else frame.nodes + np.asarray(u)[:frame.n_nodes, :3]
    top, bot, r = _surface_nodes(frame, info)
    w = float(info["wale_spacing"])
    d = float(info["seam_distance"])
    nb = int(round(d / w))
    X = x[:, 0] - float(info["seam_x"])
    k = np.mod(np.round(X / w).astype(np.int64), nb)          # bin of each node, 0 = seam line
    zt = np.full(nb, -np.inf)
    zb = np.full(nb, np.inf)
    np.maximum.at(zt, k[top], x[top, 2] + r[top])
    np.minimum.at(zb, k[bot], x[bot, 2] - r[bot])
    kk = np.arange(nb)
    centre = np.where(kk < (nb + 1) // 2, kk, kk - nb) * w    # [-d/2, d/2)
    order = np.argsort(centre)
    h = zt - zb
    return centre[order], h[order]


def thread_escape(frame, info, u) -> str:
    """'' if the stitch still holds the fabric between its threads at the seam line, else which
    thread slipped through its layer (through an opening between the yarns, or a contact missed
    in a large step): the stitch is then unloaded and the fabric floats, a state the contact
    solve accepts as an equilibrium.

    Criterion: g = mean height of the layer's nodes within half a wale of the seam line minus the
    thread's mean height (bottom layer over the bobbin thread; top layer: needle thread minus
    layer). As sewn, g = g0 > 0 (about a yarn radius). A thread pressed into its layer lowers g a
    little (the default cell at eps0 = 0.3 ends at g = -0.13 mm for the needle thread, the thread
    nestled between loop legs); a thread that went through makes g fall by millimetres. Escaped:
    g < -g0."""
    Lx = float(frame.periods[0, 0])
    layer = np.asarray(info["layer"])
    out = []
    for side, thread, sign in (("bottom", "bobbin", 1.0), ("top", "needle", -1.0)):
        nodes = np.unique(frame.elements[layer == side])
        g = []
        for xyz in (frame.nodes, frame.nodes + np.asarray(u)[:frame.n_nodes, :3]):
            dx = (xyz[nodes, 0] - float(info["seam_x"]) + 0.5 * Lx) % Lx - 0.5 * Lx
            near = nodes[np.abs(dx) < 0.5 * float(info["wale_spacing"])]
            if not len(near):
                break
            g.append(sign * (xyz[near, 2].mean() - xyz[info[f"{thread}_nodes"], 2].mean()))
        if len(g) == 2 and g[1] < -abs(g[0]):
            out.append(f"the {thread} thread slipped through the {side} layer: the layer's mean height at the "
                       f"seam line is {-g[1]:.3g} mm on the wrong side of it (as sewn {g[0]:.3g} mm on the right side)")
    return "; ".join(out)


class SeamSolver:
    """Contact solve of a seam cell with the stitch pre-strain ramped in load steps.

    Parameters
    ----------
    frame, info : from :func:`homtex.geometry.seam.seam_cell` (frame.prestrain = full eps0).
    contact : homtex.Contact (default ``Contact()``: pdas, augmented Lagrangian).
    plates : optional list of :class:`homtex.contact.Plate` (for compression after the seam).

    Supports: ux, uy of the fabric's lowest node (in-plane rigid translation of the periodic
    fabric); ux, uy, uz of the stitch's interlock node (rigid translation of the stitch) and ux of
    every stitch node (the thread stays on the seam line, held by the needle holes). The
    fabric's vertical position is held by its contacts with the stitch (no pin: the stitch and
    the fabric find their own relative height).
    """

    def __init__(self, frame, info, *, contact=None, plates=(), solver: str = "direct", geometry: str = "linear",
                 stabilize: float = 0.0):
        from ..contact.compress import _default_fixed
        from ..contact.solve import ContactSolver
        from ..analysis.static import prestrain_load

        self.frame, self.info = frame, info
        nf = int(info["fabric_nodes"])
        fix = {k: v for k, v in _default_fixed(frame, frame.nodes).items() if k < nf}
        fix[int(info["interlock_nodes"][0])] = [0, 1, 2]
        # the stitch stays in its plane x = x_s: ux of every stitch node is held (the needle holes
        # and friction keep the thread on the seam line; without it the frictionless thread can
        # turn about y through the interlock or slide off the loop heads)
        for k in range(nf, frame.n_nodes):
            fix.setdefault(k, [0])
        self.fixed = fix
        self.contact = _default_contact() if contact is None else contact
        self.cs = ContactSolver(frame, fix, None, self.contact, plates=list(plates), solver=solver)
        self.f_pre = prestrain_load(frame)
        if geometry not in GEOMETRIES:
            raise InputError(f"geometry must be one of {GEOMETRIES}, got {geometry!r}")
        self.geometry = geometry
        self.stabilize = float(stabilize)
        self.cor = None
        self.plate_u = None
        if geometry == "nonlinear":
            from ..analysis.nonlinear import Corotational

            self.cor = Corotational(frame, self.cs.assembler)
        self.alpha = 0.0
        self.u_ref = None
        self.warm = None
        self.result = None
        self.history = []
        self.retries = 0

    def _solve(self, alpha):
        """Contact solve at pre-strain factor alpha; a cycling active set is retried once from a
        cold start (active set from the gaps instead of the previous step's contacts)."""
        from ..errors import SolverError

        n = self.frame.n_nodes
        if self.cor is not None:
            from ..contact.newton import newton_contact

            def run(warm):
                res, pu, _ = newton_contact(self.cs, self.cor, prestrain_scale=alpha, plate_u=self.plate_u,
                                            warm_keys=warm, stabilize=self.stabilize)
                self.plate_u = pu
                return res
        else:
            def run(warm):
                self.cs.f[:6 * n] = alpha * self.f_pre
                return self.cs.solve(u_ref=self.u_ref, warm_keys=warm)
        try:
            return run(self.warm)
        except SolverError:
            if self.warm is None:
                raise
            self.retries += 1
            return run(None)

    def held(self, res):
        """``res`` if the stitch still holds the fabric between its threads, else SolverError
        (:func:`thread_escape`): the caller treats the step as failed and cuts it."""
        from ..errors import SolverError

        escape = thread_escape(self.frame, self.info, res.u)
        if escape:
            raise SolverError(escape)
        return res

    def _accept(self, res, alpha):
        self.alpha = alpha
        self.u_ref = res.extra["u_ext"]
        self.warm = res.extra["active_keys"]
        self.result = res

    def ramp(self, steps: int = 4, max_cuts: int = 4, time_limit: float | None = None):
        """Raise the pre-strain factor from the current value to 1 in ``steps`` equal steps; a step
        whose contact solve fails, or ends with a thread slipped through its layer
        (:func:`thread_escape`), is halved (at most ``max_cuts`` times in a row). ``time_limit``
        (s): stop with a SolverError once it is exceeded (the accepted steps are kept).
        Returns the list of (alpha, contact iterations, active contacts) of the accepted steps."""
        import time

        from ..errors import SolverError

        da = da0 = (1.0 - self.alpha) / int(steps)
        cuts = 0
        t0 = time.perf_counter()
        while self.alpha < 1.0 - 1e-12:
            if time_limit is not None and time.perf_counter() - t0 > time_limit:
                raise SolverError(f"seam pre-strain ramp: time limit {time_limit:g} s reached at {self.alpha:.4g} x eps0")
            a = min(1.0, self.alpha + da)
            try:
                res = self.held(self._solve(a))
            except (SolverError, np.linalg.LinAlgError) as err:
                if cuts >= max_cuts:
                    raise SolverError(f"seam pre-strain ramp failed at {a:.4g} x eps0 after {cuts} step cuts: "
                                      f"{err}") from err
                cuts += 1
                da *= 0.5
                continue
            self._accept(res, a)
            self.history.append((a, int(res.extra["contact_iterations"]), int(res.contacts.n_active)))
            cuts = 0
            da = min(2.0 * da, da0)            # grow back after a cut
        return self.history


def yarn_profile(cell, *, seam_distance: float, prestrain: float | None = None, steps: int = 4,
                 stitches: int = 1, exact: bool = False, contact=None, elements_per_mm: float | None = None,
                 leg_elements: int | None = None, max_cuts: int = 4, geometry: str = "linear",
                 stabilize: float = 0.0):
    """Cushion profile from the yarn-level seam cell (``seam_profile(method="yarn")``).

    Parameters
    ----------
    cell : spacer Cell with a [parameters.seam] table (stitch_length, prestrain, yarn,
        optional elements_per_mm, leg_elements) and the stitch yarn type.
    seam_distance : d, mm; rounded to a whole number of fabric repeats across the wales
        (``exact=True``: InputError instead); the effective d is returned.
    prestrain : eps0 (None: the calibrated ``[parameters.seam] prestrain``).
    steps : load steps of the pre-strain ramp (a failing step is halved, at most ``max_cuts`` times
        in a row). The contact geometry is re-linearised per step, so the answer depends somewhat on
        the steps (see the report); compare cells on the same step path.
    stitches : stitches along y in the cell (2: a 2-stitch supercell, same answer expected).
    geometry : "linear" (small rotations) or "nonlinear" (co-rotational beams, Newton iterations
        per load step: the pile yarns may tilt and buckle under the stitch); ``stabilize``: viscous
        stabilisation of the nonlinear steps (:func:`homtex.contact.nonlinear.newton_contact`).

    Returns
    -------
    xarray.Dataset: ``height`` (mm) over ``x`` (mm, (2 n_x wales,), 0 = seam line), scalars
    ``cushion_height`` (max height, mm), ``seam_height`` (height at x = 0, mm), ``stitch_force``
    (axial force of one stitch leg = two thread strands, N), ``prestrain``, ``seam_distance``
    (effective, mm); attrs status ("ok" or the failure), timings, sizes, contact statistics.
    """
    import time

    import xarray as xr

    from ..geometry.seam import seam_cell

    seam = _cell_seam_table(cell)
    eps0 = float(seam.get("prestrain", 0.0)) if prestrain is None else float(prestrain)
    if not (math.isfinite(eps0) and 0.0 <= eps0 < 1.0):
        raise InputError(f"prestrain must lie in [0, 1), got {prestrain!r}")
    epm = float(seam.get("elements_per_mm", 1.0) if elements_per_mm is None else elements_per_mm)
    nl = int(seam.get("leg_elements", 4) if leg_elements is None else leg_elements)
    t0 = time.perf_counter()
    frame, info = seam_cell(cell, seam_distance=seam_distance, prestrain=eps0, stitches=stitches, exact=exact,
                            elements_per_mm=epm, leg_elements=nl)
    t_build = time.perf_counter() - t0
    status = "ok"
    u = None
    N_leg = 0.0
    slack = 0.0
    hist = []
    iters = 0
    if eps0 > 0.0:
        from ..errors import SolverError

        try:
            ss = SeamSolver(frame, info, contact=contact, geometry=geometry, stabilize=stabilize)
            hist = ss.ramp(steps, max_cuts=max_cuts)
            res = ss.result
            u = res.u
            N_leg = float(np.mean(res.forces[info["legs"], 6]))
            # the top and bottom legs of a stitch are in series between the needle and bobbin threads:
            # pushing the seam line down by delta shortens them by delta; slack after N L / EA_leg
            xyz = frame.nodes + np.asarray(u)[:frame.n_nodes, :3]
            el = frame.elements[info["legs"]]
            L_legs = float(np.linalg.norm(xyz[el[:, 1]] - xyz[el[:, 0]], axis=1).sum()) / max(int(stitches), 1)
            slack = max(N_leg, 0.0) * L_legs / (2.0 * float(info["stitch_EA"]))
            iters = sum(h[1] for h in hist)
        except SolverError as err:
            status = f"failed: {err}"
    x, h = measure_profile(frame, info, u)
    if u is None and eps0 > 0.0:
        h = np.full_like(h, np.nan)
    seconds = time.perf_counter() - t0
    i0 = int(np.argmin(np.abs(x)))
    d_eff = float(info["seam_distance"])
    ds = xr.Dataset(
        {"height": ("x", h, {"units": "mm", "long_name": "cushion height (outer yarn surfaces, per wale bin)"}),
         "cushion_height": ((), float(np.max(h)), {"units": "mm", "long_name": "cushion height (max height between seams)"}),
         "seam_height": ((), float(h[i0]), {"units": "mm", "long_name": "height at the seam line"}),
         "stitch_force": ((), N_leg, {"units": "N", "long_name": "axial force of a stitch leg (two thread strands)"}),
         "slack_travel": ((), slack, {"units": "mm", "long_name": SLACK_LONG_NAME}),
         "prestrain": ((), eps0, {"units": "1", "long_name": "stitch-yarn pre-strain eps0"}),
         "seam_distance": ((), d_eff, {"units": "mm", "long_name": "effective seam distance (whole fabric repeats)"})},
        coords={"x": ("x", x, {"units": "mm", "long_name": "position across the seam (0 = seam line)"})})
    ds.attrs.update(
        model="yarn", method="yarn", status=status,
        validity="the yarn-level seam dips only locally (decay length ~2.6 mm): the cushion stays near the "
        "fabric thickness and does NOT reproduce measured cushion heights; eps0 is a nominal value, not "
        "calibrated (README 'Seams'; method='foundation' is the calibrated model)",
        description="yarn-level seam cell (lock stitch 301, pre-strained stitch yarn, yarn-yarn contact; "
        + ("co-rotational beams, Newton iterations per load step)" if geometry == "nonlinear" else
           "geometrically linear beams, contact re-linearised per load step)"), geometry=geometry,
        requested_seam_distance_mm=float(info["requested_seam_distance"]), effective_seam_distance_mm=d_eff,
        stitch_length_mm=float(info["stitch_length"]), stitches=int(stitches), thickness_mm=float(info["thickness"]),
        n_nodes=int(frame.n_nodes), n_elements=int(frame.n_elements), repeats_x=int(info["n_x"]),
        repeats_y=int(info["n_y"]), ramp_steps=len(hist), contact_iterations=int(iters),
        leg_clearance_mm=float(info["leg_clearance"]), seconds=seconds, build_seconds=t_build,
        stitch_elements_per_mm=epm, leg_elements=nl)
    return ds


def seam_profile(cell, *, seam_distance: float, prestrain: float | None = None, method: str = "yarn", **options):
    """Cushion profile of a spacer fabric with parallel lock-stitch seams.

    Parameters
    ----------
    cell : spacer Cell (``cells/spacer_20mm.toml``) with a [parameters.seam] table.
    seam_distance : d, mm.
    prestrain : stitch-yarn pre-strain eps0; None: the value calibrated for the method
        (yarn: ``[parameters.seam] prestrain``; foundation: ``foundation_prestrain``).
    method : "yarn" (default, :func:`yarn_profile`, the yarn-level seam cell) or "foundation"
        (:func:`foundation_profile`, the analytical beam-on-foundation model, its layer rigidity
        calibrated on d = 24 mm).
    options : passed on (yarn: steps, stitches, exact, contact, elements_per_mm, leg_elements;
        foundation: points, exact_wales).

    Returns
    -------
    xarray.Dataset with ``height`` (mm) over ``x`` (mm, 0 = seam line), scalar ``cushion_height``
    (mm), ``seam_height`` (mm), ``stitch_force`` (N), ``prestrain``; attrs ``method``, ``status``,
    ``effective_seam_distance_mm``.
    """
    if method == "yarn":
        return yarn_profile(cell, seam_distance=seam_distance, prestrain=prestrain, **options)
    if method == "foundation":
        return foundation_profile(cell, seam_distance=seam_distance, prestrain=prestrain, **options)
    raise InputError(f"seam_profile: method must be 'yarn' or 'foundation', got {method!r}")


def seam_compression(cell, *, seam_distance: float | None, strain: float = 0.3, steps: int = 30,
                     prestrain: float | None = None, contact=None, ramp_steps: int = 4, tension_only: bool = True):
    """Yarn-level compression of a seamed spacer fabric between two rigid plates (paper's Fig. 11).

    The seam cell (:func:`homtex.geometry.seam.seam_cell`) is first brought to its sewn state (the
    stitch pre-strain ramped as in :func:`yarn_profile`, plates far away); then both plates are
    moved onto the outermost yarn surfaces (stitch included) and the top plate descends by
    ``strain`` x H0 in ``steps`` equal steps, H0 = the sewn specimen's thickness (initial plate
    distance). Stitch pre-strain stays on. Contact geometry is re-linearised per step.

    Parameters
    ----------
    cell : spacer Cell with [parameters.seam].
    seam_distance : d, mm (rounded to whole fabric repeats); None: the unseamed fabric
        (``homtex.compress`` on the fabric cell with the same contact options).
    strain : final compression (plate displacement / H0), 0 < strain < 1.
    steps : plate steps. The contact geometry is re-linearised per step, so the curve depends on
        them: on the d = 24 mm cell to 30 % the default 30 steps are within 1 % of 60, 15 steps
        5 %, 8 steps 12 % - and slower, because too-large steps fail and are halved.
    prestrain : eps0 (None: ``[parameters.seam] prestrain``).
    tension_only : the stitch thread cannot carry compression (default): elements that would be
        shortened below their rest length go slack during the compression (see ``_SlackThreads``).

    Returns
    -------
    xarray.Dataset over ``strain`` (plate displacement / H0): plate_displacement (mm), force (N on the
    cell), stress (kPa, force / cell area), cushion_plate_contacts (active top-plate contacts with
    fabric nodes), cushions_touched (wale bins of the cushion profile that touch the top plate),
    stitch_plate_contacts, active_contacts; attrs status, thickness_mm (H0), area_mm2, seam_distance_mm,
    cushion_height_mm (of the sewn state), seconds.
    """
    import time

    import xarray as xr

    from ..contact import compress
    from ..contact.constraints import Plate, node_contact_radius
    from ..errors import SolverError
    from ..geometry.seam import seam_cell

    if not (0.0 < float(strain) < 1.0):
        raise InputError(f"strain must lie in (0, 1), got {strain!r}")
    if int(steps) != steps or steps < 1:
        raise InputError(f"steps must be a positive integer, got {steps!r}")
    t0 = time.perf_counter()
    if seam_distance is None:
        ds = compress(cell, strain=strain, steps=steps, contact=_default_contact() if contact is None else contact)
        ds = ds.assign(cushion_plate_contacts=ds.active_yarn_plate.astype(float) * np.nan)
        ds.cushion_plate_contacts.attrs.update(units="1", long_name="not counted for the unseamed cell")
        ds.attrs.update(seam_distance_mm=float("nan"), model="unseamed fabric cell (homtex.compress)",
                        cushion_height_mm=float(cell.info["thickness"]))
        return ds
    seam = _cell_seam_table(cell)
    eps0 = float(seam.get("prestrain", 0.0)) if prestrain is None else float(prestrain)
    frame, info = seam_cell(cell, seam_distance=seam_distance, prestrain=eps0,
                            elements_per_mm=float(seam.get("elements_per_mm", 1.0)),
                            leg_elements=int(seam.get("leg_elements", 4)))
    rn = node_contact_radius(frame)
    z = frame.nodes[:, 2]
    far = 0.5 * float(info["thickness"])
    bottom = Plate(z=float((z - rn).min()) - far, normal=1, displacement=0.0, name="bottom")
    top = Plate(z=float((z + rn).max()) + far, normal=-1, displacement=0.0, name="top")
    ss = SeamSolver(frame, info, contact=contact, plates=[bottom, top])
    status = "ok"
    rec = {k: [] for k in ("strain", "plate_displacement", "force", "stress", "cushion_plate_contacts",
                           "cushions_touched", "stitch_plate_contacts", "active_contacts",
                           "slack_stitch_elements")}
    area = float(abs(np.cross(frame.periods[0], frame.periods[1])[2]))
    nf = int(info["fabric_nodes"])
    w = float(info["wale_spacing"])
    nb = int(round(float(info["seam_distance"]) / w))
    H0 = float("nan")
    h_sewn = np.full(nb, np.nan)
    try:
        if eps0 > 0:
            ss.ramp(ramp_steps)
            u = ss.result.u
        else:
            u = np.zeros((frame.n_nodes, 6))
        _, h_sewn = measure_profile(frame, info, u)

        def touch(u):
            """Both plates onto the outermost yarn surfaces of state u; returns (H0, top displacement)."""
            x = frame.nodes + u[:, :3]
            z_lo = float((x[:, 2] - rn).min())
            z_hi = float((x[:, 2] + rn).max())
            ss.cs.set_plate(0, displacement=z_lo - bottom.z)
            ss.cs.set_plate(1, displacement=z_hi - top.z)
            return z_hi - z_lo, z_hi - top.z

        # the plates now hold the vertical position: free the interlock's uz (its reaction was zero,
        # the sewn state is self-equilibrated) so that plate loads on the stitch reach the fabric
        from ..contact.solve import ContactSolver

        fix = dict(ss.fixed)
        fix[int(info["interlock_nodes"][0])] = [0, 1]
        ss.cs = ContactSolver(frame, fix, None, ss.contact, plates=[bottom, top], solver="direct")
        slack = _SlackThreads(frame, info, ss.cs)

        def solve_step():
            return ss.held(slack.solve(ss) if tension_only else ss._solve(1.0))

        H0, d_top0 = touch(u)
        # settle with both plates just touching: freeing the interlock lets a stitch loop that the
        # pin held give way (at eps0 = 0.4 the outermost loop sank 0.19 mm at zero force, so the
        # first plate step met nothing); H0 is the settled specimen's thickness
        res0 = solve_step()
        ss._accept(res0, 1.0)
        H0, d_top0 = touch(res0.u)
        e_done = 0.0
        de = float(strain) / int(steps)
        cuts = 0
        k = 0
        while e_done < float(strain) - 1e-12:
            e = min(float(strain), e_done + de)
            ss.cs.set_plate(1, displacement=d_top0 - e * H0)
            try:
                res = solve_step()
            except (SolverError, np.linalg.LinAlgError) as err:
                if cuts < 3:
                    cuts += 1
                    de *= 0.5
                    continue
                status = f"failed at strain {e:.4g} after {cuts} step cuts: {err}"
                break
            ss._accept(res, 1.0)
            e_done = e
            k += 1
            if cuts:
                cuts = 0
                de = float(strain) / int(steps)
            c = res.contacts
            act = c.plate_active & (c.plate == 1)
            pn = c.plate_node[act]
            fab = pn[pn < nf]
            xr_ = frame.nodes[fab, 0] + res.u[fab, 0] - float(info["seam_x"])
            bins = np.unique(np.mod(np.round(xr_ / w).astype(np.int64), nb))
            F = float(res.extra["plate_force"][1])
            rec["strain"].append(e)
            rec["plate_displacement"].append(e * H0)
            rec["force"].append(F)
            rec["stress"].append(F / area * 1e3)
            rec["cushion_plate_contacts"].append(len(fab))
            rec["cushions_touched"].append(len(bins))
            rec["stitch_plate_contacts"].append(int((pn >= nf).sum()))
            rec["active_contacts"].append(int(c.n_active))
            rec["slack_stitch_elements"].append(int(slack.slack.sum()))
    except SolverError as err:
        status = f"failed in the seam pre-strain ramp: {err}"
    meta = {"strain": ("1", "compression strain (plate displacement / sewn thickness H0)"),
            "plate_displacement": ("mm", "top plate displacement from first contact"),
            "force": ("N", "plate force on the seam cell"),
            "stress": ("kPa", "compression stress (force / cell area)"),
            "cushion_plate_contacts": ("1", "active contacts between fabric nodes and the top plate"),
            "cushions_touched": ("1", "wale bins of the cushion that touch the top plate"),
            "stitch_plate_contacts": ("1", "active contacts between the needle thread and the top plate"),
            "active_contacts": ("1", "active contacts (yarn-yarn and yarn-plate)"),
            "slack_stitch_elements": ("1", "stitch elements gone slack (tension-only thread)")}
    data = {k: ("strain", np.asarray(v, float), {"units": meta[k][0], "long_name": meta[k][1]})
            for k, v in rec.items() if k != "strain"}
    ds = xr.Dataset(data, coords={"strain": ("strain", np.asarray(rec["strain"], float),
                                             {"units": "1", "long_name": meta["strain"][1]})})
    ds.attrs.update(status=status, model="yarn-level seam cell between rigid plates", thickness_mm=H0,
                    area_mm2=area, seam_distance_mm=float(info["seam_distance"]),
                    requested_seam_distance_mm=float(info["requested_seam_distance"]), prestrain=eps0,
                    cushion_height_mm=float(np.nanmax(h_sewn)), seam_height_mm=float(h_sewn[nb // 2]),
                    seconds=time.perf_counter() - t0, n_nodes=int(frame.n_nodes), tension_only=int(tension_only))
    from ..contact.compress import flag_force_drops

    return flag_force_drops(ds, what=f"seam_compression d = {float(info['seam_distance']):.4g} mm, eps0 = {eps0:g}")


class _SlackThreads:
    """Tension-only stitch thread for the linear seam cell: a stitch element whose axial force
    would be compressive (shorter than its rest length (1 - eps0) L0) goes slack - its axial
    stiffness drops by ``factor`` (it buckles; the thread's tiny bending stiffness stays) and so
    does its pre-strain load - and the step is solved again until the slack set settles.
    Without it the thread legs act as struts once the punch reaches the seam line."""

    def __init__(self, frame, info, cs, factor: float = 1e-3):
        self.frame, self.cs, self.factor = frame, cs, float(factor)
        self.stitch = np.zeros(frame.n_elements, dtype=bool)
        self.stitch[int(info["fabric_elements"]):] = True
        self.slack = np.zeros(frame.n_elements, dtype=bool)
        self.full = cs.assembler.element_arrays()

    def _apply(self, ss):
        from ..analysis.static import prestrain_load

        scale = np.where(self.slack, self.factor, 1.0)
        R, L, EA, GJ, EIy, EIz, kGA = self.full
        K = self.cs.assembler.stiffness((R, L, EA * scale, GJ, EIy, EIz, kGA))
        self.cs.set_stiffness(K)
        ss.f_pre = prestrain_load(self.frame, EA * scale)

    def solve(self, ss, max_rounds: int = 12):
        from ..errors import SolverError
        from ..analysis.static import element_state

        seen = {self.slack.tobytes()}
        for _ in range(max_rounds):
            res = ss._solve(1.0)
            N = element_state(self.frame, res.u)[0][:, 6]       # with the full properties
            new = self.stitch & (N < 0.0)
            if np.array_equal(new, self.slack):
                res.forces[np.ix_(self.slack, [0, 6])] *= self.factor
                res.energy["axial"][self.slack] *= self.factor ** 2
                return res
            if new.tobytes() in seen:
                raise SolverError(f"tension-only stitch: the slack set cycles ({int(new.sum())} slack elements)")
            seen.add(new.tobytes())
            self.slack = new
            self._apply(ss)
        raise SolverError(f"tension-only stitch: the slack set did not settle in {max_rounds} rounds")
