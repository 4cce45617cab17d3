"""Contact options: how yarns meet each other and rigid plates (``homtex.Contact``)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..validate import check_choice, check_int, check_number

__all__ = ["Contact", "ENFORCEMENTS", "STRATEGIES"]


STRATEGIES = ("pdas", "removal")

#: largest friction coefficient accepted (measured yarn coefficients are 0.1-1)
MAX_FRICTION = 10.0


ENFORCEMENTS = ("augmented", "penalty")


@dataclass
class Contact:
    """Contact options: normal contact between yarns and with rigid plates, and (with
    ``geometry="nonlinear"``) Coulomb friction.

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
    friction_slip : slip (mm) per step at which the smoothed Coulomb friction saturates (eps_v;
        below it a contact sticks elastically). Default: 1e-3 x the thinnest contact radius (1e-4 mm
        for 0.1 mm yarns): steps that slide a contact by less than eps_v see a friction force below
        mu N, so eps_v must stay well below the slip of a step on the thinnest yarns.
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
    friction_slip: float | None = None

    def __post_init__(self):
        def named(name):
            return f"Contact option '{name}'"

        check_choice(self.strategy, named("strategy"), STRATEGIES)
        check_choice(self.enforcement, named("enforcement"), ENFORCEMENTS)
        if self.penalty is not None:
            self.penalty = check_number(self.penalty, named("penalty") + " (N/mm)", gt=0.0, le=1e15)
        self.removal_fraction = check_number(self.removal_fraction, named("removal_fraction"), gt=0.0, le=1.0)
        if self.margin is not None:
            self.margin = check_number(self.margin, named("margin") + " (mm)", ge=0.0, le=1e6)
        if self.exclude_hops is not None:
            self.exclude_hops = check_int(self.exclude_hops, named("exclude_hops"), ge=1)
        for name in ("gap_tol", "max_penetration", "detect_tol", "reuse_tol", "max_forward_error"):
            setattr(self, name, check_number(getattr(self, name), named(name), gt=0.0))
        self.penalty_growth_max = check_number(self.penalty_growth_max, named("penalty_growth_max"), ge=1.0)
        for name in ("max_iter", "max_updates", "detect_rounds"):
            setattr(self, name, check_int(getattr(self, name), named(name), ge=1, le=10 ** 6))
        if not isinstance(self.reuse_amg, (bool, np.bool_)):
            raise InputError(f"{named('reuse_amg')} must be True or False, got {self.reuse_amg!r}")
        check_choice(self.initial_overlap, named("initial_overlap"), ("touch", "resolve"))
        for name in ("friction", "plate_friction"):
            if getattr(self, name) is not None:
                setattr(self, name, check_number(getattr(self, name), named(name), ge=0.0, le=MAX_FRICTION))
        self.barrier_gap = check_number(self.barrier_gap, named("barrier_gap") + " (relative to the smallest contact "
                                        "radius)", gt=0.0, le=0.5)
        if self.barrier_stiffness is not None:
            self.barrier_stiffness = check_number(self.barrier_stiffness, named("barrier_stiffness") + " (N/mm)",
                                                  gt=0.0, le=1e12)
        if self.friction_slip is not None:
            self.friction_slip = check_number(self.friction_slip, named("friction_slip") + " (mm)", gt=0.0, le=1.0)

    @property
    def has_friction(self) -> bool:
        """A nonzero friction coefficient was asked for (yarns or plates)."""
        return bool((self.friction or 0.0) > 0.0 or (self.plate_friction or 0.0) > 0.0)

    def require_frictionless(self, what: str = "the linear contact solve") -> None:
        """InputError if friction was asked for where only frictionless contact exists."""
        if self.has_friction:
            raise InputError(f"Contact option 'friction' = {self.friction!r} (plate_friction {self.plate_friction!r}): "
                             f"{what} is frictionless; Coulomb friction needs the large-motion engine, "
                             "geometry=\"nonlinear\"")
