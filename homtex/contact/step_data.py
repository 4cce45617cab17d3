"""What the large-motion step solver (:mod:`.incremental`) is told, continues from and reports:
its settings, a converged state to continue from, and what one accepted step did."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError

__all__ = ["EngineState", "NonlinearSettings", "StepInfo"]


@dataclass
class NonlinearSettings:
    """Settings of the large-motion step solver.

    tol : free residual relative to the largest of the internal, contact and applied forces.
    max_iter : Newton iterations per friction round. friction_rounds : lag updates per step
    (1: lagged at the step's start only). friction_tol : relative change of the nodes' normal
    forces below which the lag has settled. round_tol : free residual (relative, as tol) at which a
    friction round before the last stops: the lag measured there is off by about this share, far
    below friction_tol; the round whose lag has settled is then finished at tol. eta : CCD keeps
    each gap >= eta x its start.
    max_spin : largest nodal rotation per iteration, rad. delta0 : pseudo-time step at the
    first step (M / delta0 is added to the tangent); delta_max : largest one at a step's start.
    armijo : sufficient-decrease constant of the line search. predictor_slip : while prescribed
    motion is left, friction's Hessian saturates at this share of the largest prescribed
    translation instead of eps_v (measured on the spacer cell with mu = 0.2 and the capstan:
    0 (the stick stiffness) fails the capstan's sliding rope, 0.03-0.1 pass both, 1 makes the
    spacer curve 2-3x slower). stabilization : what the ledger counts as taken out at fixed
    prescribed motions: "damping" (the pseudo-viscous work sum du M du / delta) or "released"
    (the decrease of the total potential over the corrector iterations: a relaxation from a
    generated geometry, whose stored energy the solver releases, balances exactly). pattern_reach :
    when an active contact's block falls outside the tangent's pattern and the pattern is rebuilt,
    the pairs closer than pattern_reach x ghat join it too (0: only the active ones); where contacts
    appear at nearly every iteration (20 filaments per yarn settling on each other: 589 rebuilds
    in 700 Newton iterations, each a new ordering and symbolic factor) 3 cut the rebuilds to 183
    and the CPU by a fifth, more couples too much (30: 33 rebuilds, a denser factor, 14 % slower).
    exact_retry : after an iteration whose exact Hessian was indefinite (its contact blocks then
    projected to PSD), the next exact_retry - 1 iterations take the projected one at once, the
    exact one being tried again after them (1: every iteration tries the exact one first). Where
    the exact Hessian stays indefinite over many iterations (a bundle of filaments: 78 % of the
    20-filament rib's iterations), each try costs a factorisation thrown away.
    """

    tol: float = 1e-8
    max_iter: int = 80
    friction_rounds: int = 4
    friction_tol: float = 1e-3
    round_tol: float = 1e-5
    eta: float = 0.1
    max_spin: float = 0.5
    delta0: float = 1e12
    delta_max: float = 1e12
    armijo: float = 1e-4
    predictor_slip: float = 0.1
    stabilization: str = "damping"
    pattern_reach: float = 0.0
    exact_retry: int = 1


@dataclass
class EngineState:
    """A converged state of the large-motion engine to continue from (``initial=`` of
    ``homtex.solve_nonlinear``): translations ``ut`` (n, 3, mm), rotations ``Q`` (n, 3, 3), the
    pre-strain scale, the dead loads acting (n, 6; N, N mm), the plates (heights, normals, force
    pressing each force-controlled plate on the yarns, NaN for displacement control), the touch
    offsets of pairs that touched in the reference geometry, the PTC step, the energy ledger and
    (a moving lattice) the current lattice vectors (k, 3), mm."""

    n_nodes: int
    n_elements: int
    ut: np.ndarray
    Q: np.ndarray
    prestrain_scale: float
    loads: np.ndarray
    plate_z: np.ndarray
    plate_normal: np.ndarray
    plate_force: np.ndarray
    touch: tuple
    ledger: dict
    delta: float = 1e12
    periods: np.ndarray | None = None

    def check(self, frame) -> None:
        """InputError unless ``frame`` is the frame this state belongs to (same nodes and elements)."""
        if frame.n_nodes != self.n_nodes or frame.n_elements != self.n_elements:
            raise InputError(f"initial: the state belongs to a frame of {self.n_nodes} nodes and {self.n_elements} "
                             f"elements, this one has {frame.n_nodes} and {frame.n_elements}; continue a solve on "
                             "the frame it was computed on")


@dataclass
class StepInfo:
    """What one accepted step did (per step; the cumulative ledger is on the solver)."""

    iterations: int = 0
    cuts: int = 0
    ccd_limited: int = 0
    searches: int = 0
    friction_rounds: int = 0
    patterns: int = 0
    projected: int = 0
    residual: float = 0.0
    delta: float = 0.0
    stabilization: float = 0.0
    dissipation: float = 0.0
    negative_eigenvalues: int = -1
    extra: dict = field(default_factory=dict)
