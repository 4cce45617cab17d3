"""Contact with large rotations: Newton's method whose every step is a contact solve.

At the current state (translations u_k, nodal rotations Q_k) the co-rotational frame gives its
internal forces f_int and tangent K_t (:class:`homtex.analysis.nonlinear.Corotational`); the step du solves
the contact problem of the linearised frame

    min 1/2 du K_t du - (f_ext - f_int) du   subject to   g(u_k) + C(u_k) du >= 0,

i.e. :class:`~homtex.contact.solver.ContactSolver` with K = K_t, loads f_ext - f_int + K_t u_ref and the
contact rows re-detected and rebuilt at u_k. Steps repeat until the increment is below ``tol``
(relative to the mean element length; rotations in rad): the final state is in equilibrium with
the contact forces of the final active set, the contact gaps are those of the current geometry.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..errors import SolverError
from ..model.results import ENERGY_KEYS


def newton_contact(cs, cor, *, prestrain_scale: float = 1.0, plate_u=None, warm_keys=None, warm_forces=None,
                   tol: float = 1e-6, max_iter: int = 40, max_rotation: float = 0.05, max_move: float = 0.5,
                   stabilize: float = 0.0):
    """Contact equilibrium of a co-rotational frame.

    Parameters
    ----------
    cs : ContactSolver of the frame (supports, plates, contact options; its stiffness is
        replaced by the tangent at every step). Loads: ``cs.f_loads`` (dead loads) and the
        plates' forces as set by ``cs.set_plate``.
    cor : Corotational state; updated in place on success, restored on failure.
    prestrain_scale : factor on the frame's pre-strain (ramps of the stitch tension).
    plate_u : (P, 6) current plate displacements (default zeros); the prescribed ones are
        taken from the plates.
    warm_keys, warm_forces : contacts active at the previous state and their forces (warm start
        of the active set and the multipliers; later Newton steps start from the previous step's).
    tol : increment tolerance (max |du| / mean element length and max |d theta| in rad).
    stabilize : viscous stabilisation (as commercial static solvers offer for buckling): a force
        -c (u - u_0) on every node's translation, c = ``stabilize`` x its diagonal stiffness and
        u_0 the state at the start of this load step. It holds unstable modes (buckling pile
        yarns, swinging loops) that the tangent cannot see, at the price of a force that is
        reported (``extra["stabilization_force"]``, max over nodes, N) and must stay small
        against the contact forces for the answer to count as static.
    max_rotation, max_move : a Newton step that turns a node by more than ``max_rotation`` rad or
        moves it by more than ``max_move`` x the mean element length is scaled down to that size
        (damped Newton): a linearised step swings soft parts (a loosely held loop) through large
        rotations, whose linearised stretch the exact forces then see as huge axial forces.

    Returns
    -------
    (result, plate_u, iterations): the last contact solve's StaticResult with ``u`` (n, 6)
    (translations, rotation vectors), ``forces`` and ``energy`` of the co-rotational state.
    """
    n, N, P = cs.n, cs.N, cs.P
    frame = cs.frame
    state = cor.copy_state()
    pu = np.zeros((P, 6)) if plate_u is None else np.array(plate_u, dtype=float).reshape(P, 6)
    f_plate = cs.plate_load                       # plate loads (force control), never touched by K
    length = float(frame.length.mean())
    u0 = cor.ut.copy()
    cdiag = None
    hist = []
    res = None
    prev = None
    relax = 1.0
    try:
        for it in range(1, int(max_iter) + 1):
            fint = cor.evaluate(prestrain_scale)
            Kt = cor.tangent()
            if stabilize > 0.0:
                if cdiag is None:
                    cdiag = stabilize * Kt.diagonal().reshape(n, 6)[:, :3].copy()
                fint = fint.copy()
                fint[:, :3] += cdiag * (cor.ut - u0)
                d6 = np.zeros((n, 6))
                d6[:, :3] = cdiag
                Kt = (Kt + sp.diags(d6.ravel())).tocsr()
            cs.set_stiffness(Kt)
            u_ref = np.zeros((N, 6))
            u_ref[:n, :3] = cor.ut
            u_ref[n:] = pu
            ur = u_ref.ravel()
            cs.set_frame_load(cs.f_loads - fint.ravel() + cs.K @ ur[:6 * n])
            res = cs.solve(u_ref=u_ref, warm_keys=warm_keys, warm_forces=warm_forces)
            du = res.extra["u_ext"] - u_ref
            if not np.all(np.isfinite(du)):
                raise SolverError(f"Newton step {it} is not finite")
            big_rot = float(np.abs(du[:n, 3:]).max(initial=0.0))
            big_mov = float(np.abs(du[:, :3]).max(initial=0.0))
            damp = min(1.0, max_rotation / max(big_rot, 1e-300), max_move * length / max(big_mov, 1e-300))
            # a step that reverses the previous one is an active set flipping between two states
            # (a contact on the edge of opening): halve the steps until they settle between them
            flat = du[:n, :3].ravel()
            if prev is not None:
                cos = float(flat @ prev) / max(float(np.linalg.norm(flat) * np.linalg.norm(prev)), 1e-300)
                relax = 0.5 * relax if cos < -0.3 else min(1.0, 2.0 * relax)
            prev = flat.copy()
            damp *= relax
            du *= damp
            cor.update(du[:n])
            pu = u_ref[n:] + du[n:]
            warm_keys = res.extra["active_keys"]
            warm_forces = res.extra["active_forces"]
            size = max(float(np.abs(du[:n, :3]).max(initial=0.0)) / length,
                       float(np.abs(du[n:, 2]).max(initial=0.0)) / length,
                       float(np.abs(du[:n, 3:]).max(initial=0.0)))
            hist.append(size)
            if size <= tol and damp == 1.0:
                break
            if it >= 10 and damp == 1.0 and size > 0.9 * hist[-6]:
                raise SolverError(f"Newton iterations stall: increment {size:.2e} after {it} steps "
                                  f"(history {', '.join(f'{h:.1e}' for h in hist[-4:])}); a smaller load step "
                                  "is needed or the active set alternates")
        else:
            raise SolverError(f"Newton iterations did not converge in {max_iter} steps (last increment {hist[-1]:.2e}, "
                              f"tolerance {tol:g})")
    except (SolverError, np.linalg.LinAlgError):
        cor.set_state(state)
        raise
    cor.evaluate(prestrain_scale)
    res.u = cor.u()
    res.forces = cor.forces.copy()
    res.energy = dict(zip(ENERGY_KEYS, cor.energy.T.copy()))
    # support reactions: internal minus applied minus contact forces on the held DOFs
    r = np.concatenate([cor.fint.ravel() - cs.f_loads, -f_plate]) - res.extra["contact_force"]
    res.reactions = np.where(cs.mask, r, 0.0)[:6 * n].reshape(n, 6)
    ue = res.extra["u_ext"].copy()
    ue[:n] = res.u
    stab = float(np.abs(cdiag * (cor.ut - u0)).max(initial=0.0)) if cdiag is not None else 0.0
    res.extra.update(u_ext=ue, newton_iterations=it, newton_history=hist, stabilization_force=stab,
                     max_deformational_rotation=cor.max_deformational_rotation())
    return res, pu, it
