"""Seams as an analytical model: surface layers as beams on an elastic foundation (the pile).

A seam cell spans one seam distance d across the seam (x) and one stitch length s
along it (y). Each surface layer is an Euler-Bernoulli strip of bending rigidity D
(N mm^2 per stitch length) resting on the pile, a linear Winkler foundation of stiffness
k = 2 E_c s / H (N/mm per mm of x; E_c the fabric's compression modulus from the unseamed
yarn-level cell, H its thickness: a layer that moves by w towards the mid-plane while the
other layer moves by w too compresses the pile by 2 w, a strain 2 w / H). Both layers are
pulled towards the mid-plane by the stitch: one point force P per stitch and layer, repeated
every d (periodic). The layer deflection is the periodic Green's function of a beam on an
elastic foundation,

    w(x) = P beta / (2 k) * sum_n exp(-beta |x - n d|) (cos beta |x - n d| + sin beta |x - n d|),
    beta = (k / (4 D))**(1/4),

and the cushion height is h(x) = H - 2 w(x). The stitch (lock stitch 301: a needle
thread over the top layer, a bobbin thread under the bottom layer, interlocked in the
middle) has, per stitch, length L(h_s) = 2 s + 2 h_s (one length s on each face, two
vertical passes of half the local height h_s each way) and wants to be shorter by the
pre-strain eps0: rest length (1 - eps0) L(H). Its tension N = EA (L / L_rest - 1) >= 0
acts through two thread legs on each layer, P = 2 N. The seam-line height h_s solves
H - h_s = 2 P(h_s) w1(0) (w1: deflection per unit force), a scalar monotone equation.

Protocol: eps0 = ``[parameters.seam] foundation_prestrain`` (the paper's needle-thread
tension read as a pre-strain, an assumption) and D = ``layer_rigidity``, calibrated once on
d = 24 mm (:func:`calibrate_layer_rigidity`); other seam distances are predictions.
Limits: the foundation is linear (compression at the seam line is far beyond the fabric's
~30 % linear range); friction and the yarn-level stitch geometry are not resolved.
docs/seams.md tells how the model was arrived at and what it predicts.
"""

from __future__ import annotations

import logging
import math
import warnings

import numpy as np
import xarray as xr
from scipy.optimize import brentq

from ..api import compress
from ..config import option
from ..contact.options import Contact
from ..errors import InputError
from ..model.results import Status
from ..validate import check_int, check_number

log = logging.getLogger(__name__)

__all__ = ["SLACK_LONG_NAME", "calibrate_layer_rigidity", "fabric_modulus", "foundation_profile", "layer_rigidity",
           "seam_table",
           "stitch_pull"]

SLACK_LONG_NAME = "punch travel at the seam line until the stitch thread is slack (tension / stiffness)"


#: periodic images summed in the foundation's Green's function
_N_IMAGES = 30


def seam_table(cell) -> dict:
    seam = (cell.parameters or {}).get("seam")
    if not isinstance(seam, dict):
        raise InputError(f"cell {getattr(cell, 'name', '?')!r}: no [parameters.seam] table "
                         "(stitch_length, prestrain, yarn)")
    return seam


def fabric_modulus(cell, *, strain: float = 0.05, steps: int = 2) -> float:
    """Compression modulus E_c (MPa) of the unseamed cell: secant stress / strain at ``strain``.

    Uses ``homtex.compress(geometry="linear")`` (yarn level, the linear model by name, penalty contact);
    cached on the cell's info.
    The foundation model is built on this linear secant modulus by definition (its layer rigidity is
    calibrated with it), so a curve "flagged" for going beyond the linear model's validity is used;
    only a failed one raises. The foundation model's own validity is that of its calibration
    (docs/seams.md).
    """
    info = cell.info
    key = ("fabric_modulus", float(strain))
    if key in info:
        return info[key]
    ds = compress(cell, strain=strain, steps=steps, geometry="linear",
                  contact=Contact(enforcement="penalty", penalty=option("modulus_penalty")))
    if ds.attrs["status"] == Status.FAILED:
        raise InputError(f"fabric_modulus: compression of cell {cell.name!r} failed: {ds.attrs['status_detail']}")
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
    def resid(logD):
        c = cell.replace(**{"parameters.seam.layer_rigidity": float(np.exp(logD)),
                            "parameters.seam.layer_rigidity_cell": cell.fabric_fingerprint()})
        p = foundation_profile(c, seam_distance=seam_distance, prestrain=prestrain, points=61)
        return float(p.cushion_height) - float(cushion_height)

    lo, hi = np.log(bounds[0]), np.log(bounds[1])
    r_lo, r_hi = resid(lo), resid(hi)
    if r_lo * r_hi > 0:
        raise InputError(f"calibrate_layer_rigidity: cushion height {cushion_height:g} mm at seam_distance "
                         f"{seam_distance:g} mm is not reachable with D in {bounds} N mm^2 (cushion "
                         f"{r_lo + cushion_height:.3g} .. {r_hi + cushion_height:.3g} mm)")
    return float(np.exp(brentq(resid, lo, hi, xtol=1e-10)))


def _reused_calibration(cell, seam) -> str:
    """'' when the layer rigidity was calibrated on this fabric (or is computed from its yarns), else
    a warning (also issued) that a calibrated value is reused on another cell."""
    if "layer_rigidity" not in seam:
        return ""
    fp = cell.fabric_fingerprint() if hasattr(cell, "fabric_fingerprint") else ""
    cal = seam.get("layer_rigidity_cell")
    if cal is not None and fp and cal == fp:
        return ""
    where = f"a fabric with fingerprint {cal}" if cal else "an unrecorded fabric"
    msg = (f"cell {getattr(cell, 'name', '?')!r}: [parameters.seam] layer_rigidity = {seam['layer_rigidity']:g} N mm^2 "
           f"was calibrated on {where}, not on this one (fingerprint {fp}): the foundation model's cushion "
           "heights are not calibrated here; recalibrate with homtex.seams.calibrate_layer_rigidity(cell) on a "
           "measured cushion height and store it with layer_rigidity_cell = cell.fabric_fingerprint()")
    warnings.warn(msg, UserWarning, stacklevel=3)
    log.warning(msg)
    return msg


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
                       exact_wales: bool = False) -> xr.Dataset:
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
    seam = seam_table(cell)
    d = check_number(seam_distance, "seam_distance", gt=0.0, le=1e4)
    points = check_int(points, "points", ge=2, le=10 ** 6)
    if not isinstance(exact_wales, (bool, np.bool_)):
        raise InputError(f"exact_wales must be True or False, got {exact_wales!r}")
    w = cell.info["wale_spacing"]
    if exact_wales and abs(d / w - round(d / w)) > 1e-6:
        raise InputError(f"seam_distance {d:g} mm is not a multiple of the wale spacing {w:.6g} mm "
                         f"({d / w:.4g} wales); a seam cell needs a whole number of wales "
                         f"(e.g. {round(d / w) * w:.6g} mm)")
    eps0 = check_number(seam.get("foundation_prestrain", 0.0) if prestrain is None else prestrain, "prestrain",
                        ge=0.0, lt=1.0)
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
    reuse = _reused_calibration(cell, seam)
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
         "cushion_height": ((), float(h.max()),
                            {"units": "mm", "long_name": "cushion height (max height between seams)"}),
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
                    "this model; eps0 = 0.40 is the paper's machine setting read as a strain (docs/seams.md)",
                    status="ok", effective_seam_distance_mm=d,
                    seam_distance_mm=d, stitch_length_mm=s, thickness_mm=H, foundation_modulus_MPa=Ec,
                    layer_rigidity_Nmm2=D, beta_per_mm=beta, stitch_EA_N=EA)
    if reuse:
        ds.attrs["check"] = reuse
    return ds
