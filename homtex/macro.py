"""Macro cushion layer: a seamed spacer-fabric specimen under a flat punch.

Model
-----
The specimen under the square plate (area ``plate_area``, side L = sqrt(area)) is cut into
``n_columns`` strips across the seams (seams run along y, one every ``seam_distance`` d mm
along x). Strip i at x_i is a cushion column of height h_i:

- no seams: h_i = H0 (the unseamed thickness) for every column;
- with seams: h_i = h(x_i mod d) from the seam cell's cushion profile (``seam_profile``),
  times a per-cushion factor (H_c + delta_k) / H_c, where H_c is the cushion height and
  delta_k ~ Normal(0, ``height_scatter``) mm is drawn once per cushion k (seeded): real
  specimens' cushions differ. Heights are clipped to (0, H0].

Every column follows the unseamed cell's compression law sigma_u(eps) (kPa over strain
measured from H0, from ``homtex.compress`` through a :class:`homtex.Lookup`). A column of
height h < H0 is the unseamed fabric already compressed to h, so it starts at strain
eps0 = 1 - h/H0 of that law; its pre-load sigma_u(eps0) is held by the stitch thread (through
the seam line and the bent layers: over a seam cell the pile's pre-load adds up to the thread's
pull). The punch starts at H0 (plate displacement w = 0) and meets column i when
H0 - w < h_i, i.e. w > w_i = H0 - h_i; from then on the column is at strain eps = w/H0 and
carries

    pre_stress="thread" (default): sigma_i = sigma_u(eps) - sigma_u(eps0) max(0, 1 - (w - w_i) / delta_s)
    pre_stress="held":             sigma_i = sigma_u(eps) - sigma_u(eps0)
    pre_stress="released":         sigma_i = sigma_u(eps)

"thread": the stitch thread is tension-only and elastic. Pushing the fabric down by delta
shortens the thread's path and lowers its tension by (EA / L) delta; it is slack after the
slack travel delta_s = N L / EA (N its tension, L the loaded thread length, EA its axial
stiffness), and from then on the punch carries the column's whole pre-load. Column and thread
are two springs in parallel, checked column by column against that model (tests/test_macro.py). delta_s
comes with the seam profile (``slack_travel``, from the seam model's own thread tension) or is
given. The two other laws are its limits: "held" (delta_s -> infinity: a compliant, long
thread keeps its pull; the punch force rises continuously from zero, as the measured curves
do) and "released" (delta_s -> 0: a stiff thread with a small tension goes slack at once).
The yarn-level seam cell of cells/spacer_20mm.toml is of the second kind (d = 24 mm: legs of
1.8 N, delta_s = 0.09 mm; against it "thread" is 8 % off to 30 % compression, "held" 16 %,
docs/main_job.md), the fitted foundation seams slacken after 0.50-0.57 mm.
Rescaling the law to the local height (sigma_u(1 - z/h)) was rejected: it treats a
pre-compressed column as fresh fabric, with straight pile yarns it no longer has.

Total force F(w) = sum_i a_i sigma_i(w) (a_i = plate_area / n_columns), stress = F / plate_area.
Strain in the output is w / H0 (the paper's curves start from a 20 mm plate distance).

Inputs by default (a cell given, nothing injected): the unseamed law is the large-motion engine's
curve of the cell to 70 % (:func:`engine_law`: ``compress(geometry="nonlinear")`` with the cell
file's friction, 35 plate steps), the cushions come from ``seam_profile`` (the cell file's seam
method, the calibrated stitch). Both are cell computations kept in the result cache
(:mod:`homtex.cache`: memory and disk, keyed by cell content, parameters and package version), so
a repeated call costs milliseconds.
"""

from __future__ import annotations

import math
import time

import numpy as np
import xarray as xr

from .api import compress
from .cache import cached
from .errors import InputError
from .lookup import Lookup
from .model.results import Status, set_status
from .seams import seam_compression, seam_profile
from .validate import check_choice, check_int, check_number, check_seed

__all__ = ["LAW_ACCURACY", "LAW_STEPS", "LAW_STRAIN", "column_heights", "cushion_law", "engine_law", "macro_curve",
           "unseamed_law"]

PRE_STRESS = ("thread", "held", "released")
LAWS = ("columns", "cushion")

#: what each law is worth against yarn-level strips of three differing seams (docs/seams.md)
LAW_ACCURACY = {
    "columns": "column model: 26-40 % off yarn-level strips to 50 % (largest stress difference over the strip's "
               "stress at 50 %; too stiff early); law='cushion' is 1.3 % off (docs/seams.md)",
    "cushion": "each cushion on the seam cell's yarn-level curve: 1.3 % off a yarn-level strip to 50 % (largest "
               "stress difference over the strip's stress at 50 %; docs/seams.md)",
    "none": "no seams: every column on the unseamed compression law itself"}

#: the default unseamed law: the engine's curve to this strain in this many plate steps
LAW_STRAIN = 0.7
LAW_STEPS = 35


def engine_law(cell, *, strain: float = LAW_STRAIN, steps: int = LAW_STEPS, contact=None, cache: bool = True):
    """The unseamed compression law of ``cell`` on the large-motion engine (``compress(cell,
    geometry="nonlinear")`` on :func:`homtex.seams.compress.strain_levels`, the cell file's friction
    unless ``contact`` says otherwise), from the result cache when computed before."""
    from .seams.compress import strain_levels

    levels = strain_levels(strain, steps)

    def compute():
        return compress(cell, strain=levels, geometry="nonlinear", contact=contact)

    if not cache:
        return compute()
    return cached("law", cell, {"levels": levels, "contact": contact}, compute)


def cushion_law(cell, *, seam_distance: float, strain: float = LAW_STRAIN, steps: int = LAW_STEPS,
                cache: bool = True, prestrain: float | None = None):
    """The seamed cushion's own compression law: the sewn seam cell of ``cell`` under the punch on
    the large-motion engine (``seam_compression(cell, seam_distance=d, strain=strain, steps=steps)``:
    ``stress`` kPa over ``strain`` = plate travel / unseamed thickness), kept in the result cache
    (the sewn state too): the first call sews and presses (minutes), a repeated one costs
    milliseconds. A failed press is returned (with its status) and not stored on disk.
    ``prestrain``: another length-controlled stitch than the calibrated one (None)."""
    kw = {"seam_distance": float(seam_distance), "strain": float(strain), "steps": int(steps)}
    if prestrain is not None:
        kw["prestrain"] = float(prestrain)
    if not cache:
        return seam_compression(cell, cache=False, **kw)
    return cached("cushion_law", cell, kw, lambda: seam_compression(cell, **kw))


def _thickness(cell, curve, thickness):
    if thickness is not None:
        H0 = float(thickness)
    elif curve is not None and hasattr(curve, "attrs") and "thickness_mm" in curve.attrs:
        H0 = float(curve.attrs["thickness_mm"])
    elif cell is not None and isinstance(getattr(cell, "info", None), dict) and "thickness" in cell.info:
        H0 = float(cell.info["thickness"])
    else:
        raise InputError("macro_curve: the unseamed thickness H0 is unknown; pass thickness=, a cell whose "
                         "info has 'thickness', or a compression curve with attrs['thickness_mm']")
    if not (math.isfinite(H0) and H0 > 0):
        raise InputError(f"macro_curve: thickness must be positive (mm), got {H0!r}")
    return H0


def unseamed_law(curve):
    """(law(eps) -> stress kPa, eps_max) from a compression Dataset, a Lookup or a callable.

    Dataset: ``stress`` (kPa) over ``strain`` (the point (0, 0) is prepended if missing);
    callable: vectorised stress_kPa(strain), eps_max = inf.
    """

    if callable(curve) and not isinstance(curve, Lookup):
        return (lambda e: np.asarray(curve(np.asarray(e, dtype=float)), dtype=float)), math.inf
    if isinstance(curve, Lookup):
        if curve.names != ["strain"]:
            raise InputError(f"macro_curve: a Lookup curve must have the single input 'strain', got {curve.names}")
        return (lambda e: curve(np.asarray(e, dtype=float).reshape(-1, 1)).reshape(np.shape(e))), float(curve.hi[0])
    if not hasattr(curve, "data_vars") or "stress" not in curve or "strain" not in curve.coords:
        raise InputError("macro_curve: curve must be a Dataset with 'stress' (kPa) over 'strain', a Lookup or "
                         "a callable")
    eps = np.asarray(curve["strain"].values, dtype=float)
    sig = np.asarray(curve["stress"].values, dtype=float)
    ok = np.isfinite(eps) & np.isfinite(sig)
    eps, sig = eps[ok], sig[ok]
    if eps.size == 0:
        raise InputError(f"macro_curve: the compression curve has no finite points "
                         f"(status: {curve.attrs.get('status', 'unknown')})")
    if eps[0] > 0:
        eps, sig = np.r_[0.0, eps], np.r_[0.0, sig]
    lk = Lookup.from_grid({"strain": eps}, sig, output="stress", units="kPa",
                          long_name="unseamed compressive stress", compute_holdout=False, extrapolate=True)
    return (lambda e: lk(np.asarray(e, dtype=float).reshape(-1, 1)).reshape(np.shape(e))), float(eps[-1])


def _profile_fn(profile, d):
    """(h(x_local) for x_local in [0, d), cushion height, slack travel mm or None) from a
    Dataset or callable."""
    if callable(profile) and not hasattr(profile, "data_vars"):
        xs = np.linspace(0.0, d, 401)[:-1]
        return (lambda x: np.asarray(profile(x, d), dtype=float)), float(np.max(profile(xs, d))), None
    if not hasattr(profile, "data_vars") or "height" not in profile or "x" not in profile.coords:
        raise InputError("macro_curve: profile must be a Dataset with 'height' (mm) over 'x' (mm) "
                         "or a callable h(x, seam_distance)")
    x = np.asarray(profile["x"].values, dtype=float)
    h = np.asarray(profile["height"].values, dtype=float)
    if not (np.isfinite(x).all() and np.isfinite(h).all()) or x.size < 2:
        raise InputError("macro_curve: the seam profile has non-finite or too few points")
    order = np.argsort(x)
    x, h = x[order], h[order]  # x = 0 is the seam line; the profile repeats every d
    hc = float(profile["cushion_height"]) if "cushion_height" in profile else float(h.max())
    slack = float(profile["slack_travel"]) if "slack_travel" in profile else None
    return (lambda q: np.interp(q, x, h, period=d)), hc, slack


def column_heights(H0: float, *, seam_distance=None, profile=None, height_scatter: float = 0.0,
                   plate_area: float = 12100.0, n_columns: int = 440, seed=None, seam_offset: float = 0.0):
    """Column centres x (n,) mm, heights h (n,) mm and cushion index (n,) under the plate."""
    L = math.sqrt(plate_area)
    x = (np.arange(n_columns) + 0.5) * (L / n_columns)
    if seam_distance is None:
        return x, np.full(n_columns, float(H0)), np.zeros(n_columns, dtype=np.int64)
    d = float(seam_distance)
    h_of, hc, _ = _profile_fn(profile, d)
    xs = x - seam_offset
    cushion = np.floor(xs / d).astype(np.int64)
    h = h_of(np.mod(xs, d))
    if height_scatter:
        h = h * ((hc + cushion_shifts(cushion, height_scatter, seed)) / hc)
    return x, np.clip(h, 1e-9, H0), cushion - cushion.min()


def cushion_shifts(cushion, height_scatter: float, seed) -> np.ndarray:
    """Per column (n,): the height difference delta_k (mm) of its cushion k from the nominal one,
    drawn once per cushion ~ Normal(0, ``height_scatter``) (seeded)."""
    cushion = np.asarray(cushion, dtype=np.int64)
    if not height_scatter:
        return np.zeros(cushion.shape)
    rng = np.random.default_rng(seed)
    k0 = cushion.min()
    return rng.normal(0.0, float(height_scatter), cushion.max() - k0 + 1)[cushion - k0]


def _cell_inputs(cell, curve, profile, seam_distance, strain, compress_options, profile_options):
    """(curve, profile, seconds spent computing them) of macro_curve: what was not injected comes
    from the cell (the engine's law and the sewn profile, both cached)."""
    t_sub = 0.0
    if curve is None:
        if cell is None:
            raise InputError("macro_curve: give a cell or a compression curve")
        ts = time.perf_counter()
        if compress_options:
            curve = compress(cell, strain=strain, **compress_options)
        else:
            curve = engine_law(cell, strain=max(float(strain), LAW_STRAIN))
        t_sub += time.perf_counter() - ts
    if seam_distance is not None and profile is None:
        if cell is None:
            raise InputError("macro_curve: seam_distance needs a cell or a profile")
        ts = time.perf_counter()
        profile = seam_profile(cell, seam_distance=seam_distance, **(profile_options or {}))
        t_sub += time.perf_counter() - ts
    return curve, profile, t_sub



def _input_status(curve) -> tuple[str, str]:
    """(status, what it says) of an input law: a Dataset's status attrs; ("", "unknown") for a
    function or a Dataset without them."""
    attrs = getattr(curve, "attrs", {})
    return attrs.get("status", ""), attrs.get("status_detail", attrs.get("status", "unknown"))


def _final_status(status: Status, detail: str, fail: str, mode: str, curve, cushion_curve) -> tuple[Status, str]:
    """(status, detail) of a macro curve: failed where the cushion's curve ended short (``fail``),
    else flagged where the law it was built on (the unseamed curve for "columns", the cushion's
    curve for "cushion": Datasets, or functions without a status) is flagged (a ledger check that
    failed on the yarn-level path)."""
    if fail:
        return Status.FAILED, fail
    what, law = (("unseamed compression curve", curve) if mode == "columns" else
                 ("cushion's yarn-level curve", cushion_curve))
    law_status, why = _input_status(law)
    if status is not Status.OK or law_status != "flagged":
        return status, detail
    return Status.FLAGGED, f"the {what} is flagged: {why}"


def _cushion_force(cell, cushion_curve, seam_distance, strain, eps, eps_end, H0, cushion, height_scatter, seed, a):
    """(force (steps,) N, failure detail or '', seconds spent on the curve, the curve): the "cushion" law of
    :func:`macro_curve`, every column on the cushion's own curve shifted by its cushion's height
    difference (NaN past the curve's end)."""
    t0 = time.perf_counter()
    shift = cushion_shifts(cushion, height_scatter, seed) / H0      # (n_columns,) strain
    need = eps_end + max(float(shift.max(initial=0.0)), 0.0)     # the tallest cushion is the furthest in
    if cushion_curve is None:
        if cell is None:
            raise InputError("macro_curve(law='cushion'): give a cell or a cushion_curve")
        # pressed as far as the tallest cushion goes, in the default law's 2 % plate steps (the sewn
        # press can stop where the punch meets a cascade of buckling legs, docs/seams.md; a press that
        # fails is not kept on disk)
        dstep = LAW_STRAIN / LAW_STEPS
        n = max(1, math.ceil(min(need, 0.98) / dstep - 1e-9))
        cushion_curve = cushion_law(cell, seam_distance=float(seam_distance), strain=n * dstep, steps=n)
    t_curve = time.perf_counter() - t0
    claw, c_max = unseamed_law(cushion_curve)
    fail = ""
    if c_max < need - 1e-12:
        why = _input_status(cushion_curve)[1]
        fail = f"the cushion's curve ends at strain {c_max:.4g} < {need:.4g} (its status: {why}); curve truncated"
    e_col = np.clip(eps[:, None] + shift[None, :], 0.0, None)
    sig = np.where(e_col <= c_max + 1e-12, claw(np.minimum(e_col, c_max)), np.nan)
    return sig.sum(axis=1) * a * 1e-3, fail, t_curve, cushion_curve

def macro_curve(cell=None, *, seam_distance=None, height_scatter: float = 0.0, plate_area: float = 12100.0,
                strain: float = 0.5, seed=None, curve=None, profile=None, n_columns: int = 440,
                steps: int = 201, thickness: float | None = None, pre_stress: str = "thread",
                slack_travel: float | None = None, seam_offset: float = 0.0, compress_options: dict | None = None,
                profile_options: dict | None = None, law: str = "columns", cushion_curve=None) -> xr.Dataset:
    """Force-compression curve of a (seamed) specimen under a flat punch: the cushion layer.

    Parameters
    ----------
    cell : the unseamed spacer cell (homtex Cell). Used for what is not injected: the
        compression law (:func:`engine_law`, the engine's curve to 70 %, cached; with
        ``compress_options``: ``homtex.compress(cell, strain=strain, **compress_options)``), the
        seam profile (``homtex.seam_profile(cell, seam_distance=d, **profile_options)``, cached)
        and H0 (``info["thickness"]``).
    seam_distance : d, mm (None: no seams, all columns H0).
    height_scatter : standard deviation of the cushion-to-cushion height, mm (seeded by ``seed``).
    plate_area : punch area, mm^2 (121 cm^2, DIN EN ISO 3386-1); strain : final plate travel / H0.
    curve : unseamed law: Dataset (``stress`` kPa over ``strain``), Lookup over "strain" or a
        vectorised callable stress_kPa(strain).
    profile : seam profile: Dataset (``height`` mm over ``x`` mm, scalar ``cushion_height``)
        or a callable h(x_local (n,), seam_distance) -> (n,) mm.
    n_columns : strips across the plate; steps : plate positions (0 .. strain H0).
    thickness : H0, mm (default from the curve's ``thickness_mm`` attribute or the cell).
    pre_stress : "thread" (default), "held" or "released": who carries a pre-compressed column's
        pre-load once the punch is on it (see the module docstring).
    slack_travel : delta_s, mm: punch travel past a column's first contact after which the
        stitch thread is slack ("thread" only). None: the profile's ``slack_travel``.
    seam_offset : position of a seam line from the plate edge, mm (profile x = 0 is a seam line).
    compress_options, profile_options : keyword arguments for ``homtex.compress`` and
        ``homtex.seam_profile`` (e.g. ``{"method": "foundation"}``) where they are called.
    law : "columns" (default; module docstring) or "cushion": every cushion on the sewn cell's own
        yarn-level curve (``cushion_curve``, a Dataset with ``stress`` kPa over ``strain`` from H0, or
        :func:`cushion_law`), shifted by its height difference delta_k in plate travel. Worth:
        :data:`LAW_ACCURACY` (in the result's attrs; "cushion" first presses the cell, minutes).

    Returns
    -------
    xarray.Dataset over ``plate_displacement`` (steps,) mm with ``force`` (N), ``stress`` (kPa),
    ``strain`` (1), ``engaged_fraction`` (1); ``column_height`` (n_columns,) mm over
    ``column_x``; attrs: H0, cushion heights, model settings, ``seconds``, status ("failed": a law
    ends short of the travel; "flagged": the law it is built on is flagged).
    """
    t0 = time.perf_counter()
    check_choice(pre_stress, "pre_stress", PRE_STRESS)
    mode = check_choice(law, "law", LAWS)       # (below, ``law`` is the unseamed law's function)
    if mode == "cushion" and seam_distance is None:
        raise InputError("macro_curve(law='cushion') needs seam_distance (mm); no seams: law='columns'")
    if slack_travel is not None:   # inf allowed: the "held" limit
        slack_travel = check_number(slack_travel, "slack_travel", ge=0.0, finite=False)
    strain = check_number(strain, "strain", gt=0.0, lt=1.0)
    plate_area = check_number(plate_area, "plate_area", gt=0.0, le=1e12)
    n_columns = check_int(n_columns, "n_columns", ge=1, le=10 ** 6)
    steps = check_int(steps, "steps", ge=2, le=10 ** 6)
    height_scatter = check_number(height_scatter, "height_scatter", ge=0.0, le=1e3)
    seam_offset = check_number(seam_offset, "seam_offset", ge=-1e6, le=1e6)
    seed = check_seed(seed)
    if seam_distance is not None:
        seam_distance = check_number(seam_distance, "seam_distance", gt=0.0, le=1e4)
    elif profile is not None:
        raise InputError("macro_curve: a profile needs its seam_distance (mm); without seams give neither")
    thickness = None if thickness is None else check_number(thickness, "thickness", gt=0.0, le=1e4)
    for name, opts in (("compress_options", compress_options), ("profile_options", profile_options)):
        if opts is not None and not isinstance(opts, dict):
            raise InputError(f"{name} must be a dict of keyword arguments, got {type(opts).__name__}")
    curve, profile, t_sub = _cell_inputs(cell, curve, profile, seam_distance, strain, compress_options,
                                         profile_options)
    H0 = _thickness(cell, curve, thickness)
    law, eps_max = unseamed_law(curve)
    status, detail, fail = Status.OK, "", ""
    eps_end = float(strain)
    if eps_max < strain - 1e-12:
        eps_end = eps_max
        why = _input_status(curve)[1]
        status, detail = Status.FAILED, (f"the unseamed compression curve ends at strain {eps_max:.4g} < "
                                         f"{strain:.4g} (its status: {why}); curve truncated")
    x, h, cushion = column_heights(H0, seam_distance=seam_distance, profile=profile, height_scatter=height_scatter,
                                   plate_area=plate_area, n_columns=int(n_columns), seed=seed,
                                   seam_offset=seam_offset)
    w = np.linspace(0.0, eps_end * H0, int(steps))
    eps = w / H0
    eps0 = 1.0 - h / H0
    a = plate_area / n_columns
    # column i is engaged when w > H0 - h_i  <=>  eps > eps0_i. With eps0 sorted, the engaged
    # columns at eps are the first k(eps) (searchsorted) and
    #   F = a [k sigma_u(eps) - sum_{i<k} sigma_u(eps0_i)]   ("held"),   F = a k sigma_u(eps)   ("released"):
    # O((n_columns + steps) log n_columns), no (steps, n_columns) array.
    e0 = np.sort(eps0)
    k = np.searchsorted(e0, eps, side="left")  # number of columns with eps0 < eps
    total = k * law(eps)
    delta = None
    if pre_stress == "thread" and seam_distance is not None:
        delta = slack_travel if slack_travel is not None else _profile_fn(profile, float(seam_distance))[2]
        if delta is None:
            raise InputError("macro_curve: pre_stress='thread' needs the stitch thread's slack travel: give "
                             "slack_travel= (mm) or a seam profile with a 'slack_travel' variable "
                             "(homtex.seam_profile writes one)")
        delta = float(delta)
    if pre_stress == "held" or (pre_stress == "thread" and delta is not None):
        # pre-load c_i = sigma_u(eps0_i) of the engaged columns (sorted, so a prefix), minus what the
        # thread has handed to the punch. With w_i = eps0_i H0, the thread still holds
        #   c_i (1 - (w - w_i) / delta)  for  w - delta < w_i < w:
        # two prefix sums (of c_i and c_i w_i), O((n_columns + steps) log n_columns), no (steps, n) array.
        c = law(np.minimum(e0, eps_end))
        cum = np.r_[0.0, np.cumsum(c)]
        if pre_stress == "held" or math.isinf(delta):
            held = cum[k]
        elif delta == 0.0:
            held = np.zeros_like(eps)
        else:
            wi = e0 * H0
            cw = np.r_[0.0, np.cumsum(c * wi)]
            j = np.searchsorted(wi, w - delta, side="right")  # columns with w_i <= w - delta are released
            held = (1.0 - w / delta) * (cum[k] - cum[j]) + (cw[k] - cw[j]) / delta
        total = total - held
    force = total * a * 1e-3  # kPa mm^2 -> N
    if mode == "cushion":
        force, fail, t_c, cushion_curve = _cushion_force(cell, cushion_curve, seam_distance, strain, eps, eps_end,
                                                         H0, cushion, height_scatter, seed, a)
        t_sub += t_c
    status, detail = _final_status(status, detail, fail, mode, curve, cushion_curve)
    frac = k / n_columns
    seconds = time.perf_counter() - t0 - t_sub
    per = {k: float(h[cushion == k].max()) for k in np.unique(cushion)}
    ds = xr.Dataset(
        {"force": ("plate_displacement", force, {"units": "N", "long_name": "punch force"}),
         "stress": ("plate_displacement", force / plate_area * 1e3,
                    {"units": "kPa", "long_name": "nominal compressive stress (force / plate area)"}),
         "engaged_fraction": ("plate_displacement", frac,
                              {"units": "1", "long_name": "fraction of the plate area in contact"}),
         "column_height": ("column_x", h, {"units": "mm", "long_name": "cushion column height before loading"}),
         "column_cushion": ("column_x", cushion, {"units": "1", "long_name": "cushion index of the column"})},
        coords={"plate_displacement": ("plate_displacement", w,
                                       {"units": "mm", "long_name": "punch displacement from the unseamed thickness"}),
                "strain": ("plate_displacement", eps,
                           {"units": "1", "long_name": "compression strain (plate displacement / unseamed thickness)"}),
                "column_x": ("column_x", x, {"units": "mm", "long_name": "column centre across the seams"})},
        attrs={"model": ("macro cushion layer (columns engaged one after another)" if mode == "columns" else
                         "macro cushion layer (each cushion on the sewn seam cell's own yarn-level curve, shifted by "
                         "its height)"), "law": mode, "thickness_mm": H0,
               "plate_area_mm2": float(plate_area),
               "seam_distance_mm": "none" if seam_distance is None else float(seam_distance),
               "height_scatter_mm": float(height_scatter), "seed": "none" if seed is None else int(seed),
               "n_columns": int(n_columns), "pre_stress": pre_stress, "seam_offset_mm": float(seam_offset),
               "slack_travel_mm": "none" if delta is None else float(delta),
               "cushion_height_mean_mm": float(np.mean(list(per.values()))),
               "cushion_height_min_mm": float(min(per.values())), "cushion_height_max_mm": float(max(per.values())),
               "first_contact_mm": float(H0 - h.max()), "full_contact_mm": float(H0 - h.min()),
               "law_accuracy": LAW_ACCURACY[mode if seam_distance is not None else "none"],
               "seconds": seconds, "seconds_inputs": t_sub})
    return set_status(ds, status, detail)
