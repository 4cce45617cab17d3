"""Contact options: how yarns meet each other and rigid plates (``homtex.Contact``)."""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from ..errors import InputError
from ..model.compression import YarnCompression
from ..validate import check_choice, check_int, check_number

__all__ = ["Contact", "ENFORCEMENTS", "LINEAR_ONLY", "STRATEGIES"]


STRATEGIES = ("pdas", "removal")

#: largest friction coefficient accepted (measured yarn coefficients are 0.1-1)
MAX_FRICTION = 10.0


ENFORCEMENTS = ("augmented", "penalty")

#: the options of the linear contact solve (active set, enforcement, its linear systems) that the
#: large-motion engine does not have; ``margin`` is shared, the barrier and friction options are
#: the engine's
LINEAR_ONLY = ("strategy", "enforcement", "penalty", "removal_fraction", "exclude_hops", "gap_tol", "max_penetration",
               "max_iter", "max_updates", "reuse_amg", "reuse_tol", "detect_rounds", "detect_tol",
               "penalty_growth_max", "initial_overlap", "max_forward_error")


@dataclass
class Contact:
    """Contact options: normal contact between yarns and with rigid plates, and (with
    ``geometry="nonlinear"``) Coulomb friction.

    The active-set, enforcement and linear-system options (:data:`LINEAR_ONLY`: ``strategy`` to
    ``initial_overlap``, and ``max_forward_error``) belong to the linear contact solve
    (``solve_static``, ``compress(geometry="linear")``); ``friction`` to ``compression`` to the
    large-motion engine (``compress``'s default, ``solve_nonlinear``); ``margin`` to both.
    ``compress`` on the engine refuses a linear-only option set away from its default.

    Parameters
    ----------
    strategy : "pdas" (primal-dual active set) or "removal" (the paper's algorithm).
    enforcement : "augmented" (exact gaps, Uzawa updates) or "penalty".
    penalty : contact stiffness k = 1/gamma, N/mm. Default: the mean translational diagonal
        of the frame stiffness (about EA/L of an element).
    removal_fraction : share of the attracting contacts removed per iteration ("removal"), (0, 1].
    margin : search distance added to r_a + r_b, mm (default: the largest contact radius).
    exclude_hops : same-yarn elements this many elements apart or closer are never in
        contact (default: enough to cover the contact diameter, at least 2).
    gap_tol : gap accuracy of "augmented", relative to the mean contact radius.
    max_penetration : largest accepted overlap of "penalty", relative to the smallest contact radius.
    detect_tol : after a solve, pairs not yet candidates that overlap by more than
        detect_tol x smallest contact radius are added and the step re-solved (up to detect_rounds).
    max_iter : active-set iterations; max_updates : multiplier updates per active set.
    reuse_amg : reuse the AMG hierarchy across contact iterations ...
    reuse_tol : ... when at most this share of the active rows changed since it was built (pdas).
    penalty_growth_max : "augmented" multiplies the penalty by 10 (up to this factor) while the
        Uzawa updates contract slowly (nearly dependent contacts).
    initial_overlap : "touch" (default): yarn pairs that overlap in the undeformed frame (a geometry
        artefact) count as touching: their gap is offset to zero, they may separate but not
        overlap further; "resolve": they are pushed apart in the first solve.
    friction : Coulomb coefficient of every yarn-yarn and yarn-plate contact (>= 0). None
        (default): the cell file's ``[contact]`` table where a cell gives one, else 0. Friction
        needs the large-motion engine (``geometry="nonlinear"``); the linear contact solve is
        frictionless and refuses a nonzero value.
    plate_friction : coefficient of yarn-plate contacts (default: ``friction``, or the cell
        file's ``plate`` entry).
    barrier_gap : activation gap of the large-motion barrier (ghat), relative to the smallest
        contact radius (default 0.01: forces act from 1 % of the thinnest yarn's radius on,
        and the contact surfaces are found to within that distance).
    barrier_stiffness : barrier stiffness kappa, N/mm (default: the mean axial stiffness EA / L
        of the elements).
    parallel_sagitta : the largest error of the nodal (line-contact) form that near-parallel yarn
        pairs use, where two elements cross at a small angle, as a share of ghat (default 0.3;
        :class:`~homtex.contact.potential.Enforcement`): the blend angles of a pair of long elements
        are lowered until their ends are at most this much farther apart than the crossing. The
        barrier can push such a crossing apart with at most about kappa ghat / parallel_sagitta;
        a larger line load closes it against the collision check and Newton stalls (a bundle of
        filaments at a knit's lock-up: docs/contact.md).
    friction_slip : slip (mm) per step at which the smoothed Coulomb friction saturates (eps_v;
        below it a contact sticks elastically). Default: 1e-3 x the thinnest contact radius (1e-4 mm
        for 0.1 mm yarns): steps that slide a contact by less than eps_v see a friction force below
        mu N, so eps_v must stay well below the slip of a step on the thinnest yarns.
    compression : a :class:`~homtex.model.compression.YarnCompression` (large-motion engine):
        yarns with a soft shell over a hard core that flatten where they cross (force k delta^n
        of the outer surfaces' overlap delta; the barrier acts at the cores). None (default):
        solid yarns of their contact radius.
    max_forward_error : with the direct solver, each solve is refined once; a relative
        correction above this (an ill-conditioned system, e.g. a penalty far above the beam
        stiffness) raises SolverError instead of returning an inaccurate state.
    """

    strategy: str = "pdas"
    enforcement: str = "augmented"
    penalty: float | None = None
    removal_fraction: float = 0.25
    margin: float | None = None
    exclude_hops: int | None = None
    gap_tol: float = 1e-9
    max_penetration: float = 0.05
    max_iter: int = 200
    max_updates: int = 100
    reuse_amg: bool = True
    reuse_tol: float = 0.05
    detect_rounds: int = 5
    detect_tol: float = 1e-3
    friction: float | None = None
    penalty_growth_max: float = 1e4
    initial_overlap: str = "touch"
    max_forward_error: float = 1e-6
    plate_friction: float | None = None
    barrier_gap: float = 0.01
    barrier_stiffness: float | None = None
    parallel_sagitta: float = 0.3
    friction_slip: float | None = None
    compression: YarnCompression | None = None

    def __setattr__(self, name, value):
        """Every assignment is checked like the constructor's arguments: ``c.friction = -5`` raises
        InputError instead of leaving an invalid option for a solve to ignore; an unknown name (a
        typo such as ``c.fricton``) is refused too."""
        check = _CHECKS.get(name)
        if check is None:
            raise InputError(f"Contact has no option {name!r}; options are {sorted(_CHECKS)}")
        object.__setattr__(self, name, check(value))

    def __delattr__(self, name):
        raise InputError(f"Contact options cannot be deleted ({name!r}); set a value instead")

    @property
    def has_friction(self) -> bool:
        """A nonzero friction coefficient was asked for (yarns or plates)."""
        return bool((self.friction or 0.0) > 0.0 or (self.plate_friction or 0.0) > 0.0)

    def linear_only(self) -> dict:
        """{name: value} of the options in :data:`LINEAR_ONLY` set away from their defaults: what
        the large-motion engine would ignore."""
        return {f.name: getattr(self, f.name) for f in fields(self)
                if f.name in LINEAR_ONLY and getattr(self, f.name) != f.default}

    def require_frictionless(self, what: str = "the linear contact solve") -> None:
        """InputError if friction (or a compressible yarn law) was asked for where only
        frictionless contact of solid yarns exists."""
        if self.compression is not None:
            raise InputError(f"Contact option 'compression': {what} has solid yarns; a compressible yarn law needs "
                             "the large-motion engine, geometry=\"nonlinear\"")
        if self.has_friction:
            raise InputError(f"Contact option 'friction' = {self.friction!r} (plate_friction {self.plate_friction!r}): "
                             f"{what} is frictionless; Coulomb friction needs the large-motion engine, "
                             "geometry=\"nonlinear\"")


def _named(name: str) -> str:
    return f"Contact option '{name}'"


def _optional(check):
    return lambda v: None if v is None else check(v)


def _bool(name):
    def check(v):
        if not isinstance(v, (bool, np.bool_)):
            raise InputError(f"{_named(name)} must be True or False, got {v!r}")
        return bool(v)
    return check


def _choice(name, choices):
    return lambda v: check_choice(v, _named(name), choices)


def _num(name, unit="", **bounds):
    return lambda v: check_number(v, _named(name) + unit, **bounds)


def _int(name, **bounds):
    return lambda v: check_int(v, _named(name), **bounds)


def _compression(v):
    if v is not None and not isinstance(v, YarnCompression):
        raise InputError(f"{_named('compression')} must be a homtex.YarnCompression or None, got {type(v).__name__}")
    return v


#: the check of every Contact option (run by the constructor and on every assignment)
_CHECKS = {
    "strategy": _choice("strategy", STRATEGIES),
    "enforcement": _choice("enforcement", ENFORCEMENTS),
    "penalty": _optional(_num("penalty", " (N/mm)", gt=0.0, le=1e15)),
    "removal_fraction": _num("removal_fraction", gt=0.0, le=1.0),
    "margin": _optional(_num("margin", " (mm)", ge=0.0, le=1e6)),
    "exclude_hops": _optional(_int("exclude_hops", ge=1)),
    **{name: _num(name, gt=0.0) for name in ("gap_tol", "max_penetration", "detect_tol", "reuse_tol",
                                              "max_forward_error")},
    "penalty_growth_max": _num("penalty_growth_max", ge=1.0),
    **{name: _int(name, ge=1, le=10 ** 6) for name in ("max_iter", "max_updates", "detect_rounds")},
    "reuse_amg": _bool("reuse_amg"),
    "initial_overlap": _choice("initial_overlap", ("touch", "resolve")),
    **{name: _optional(_num(name, ge=0.0, le=MAX_FRICTION)) for name in ("friction", "plate_friction")},
    "barrier_gap": _num("barrier_gap", " (relative to the smallest contact radius)", gt=0.0, le=0.5),
    "barrier_stiffness": _optional(_num("barrier_stiffness", " (N/mm)", gt=0.0, le=1e12)),
    "parallel_sagitta": _num("parallel_sagitta", " (a share of the barrier gap)", gt=0.0, le=1.0),
    "friction_slip": _optional(_num("friction_slip", " (mm)", gt=0.0, le=1.0)),
    "compression": _compression,
}
