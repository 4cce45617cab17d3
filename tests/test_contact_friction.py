"""Lagged smoothed Coulomb friction: the mollifier against ipctk, derivatives by finite
differences, Coulomb's law (mu lambda when sliding, less when sticking), the dissipated energy,
a pressed node that sticks below F = mu N and slides at it, and friction coefficient tables."""

import numpy as np
import pytest

from homtex.contact.ccd import plate_step_bound
from homtex.contact.examples import thick_crossing
from homtex.contact.friction import (
    _mollifier,
    contact_patches,
    friction_coefficients,
    friction_mollifier,
    friction_potential,
    pair_friction_lag,
    patch_shares,
    plate_friction_lag,
)
from homtex.contact.plates import plate_potential
from homtex.contact.potential import Enforcement, pair_potential
from homtex.contact.stencil import pair_stencil
from homtex.errors import InputError

ipctk = pytest.importorskip("ipctk")

EL2 = np.array([[0, 1], [2, 3]])
ENF = Enforcement("barrier", ghat=0.01, kappa=1.0)


def rel(a, b):
    a, b = np.asarray(a, float), np.asarray(b, float)
    return float(np.abs(a - b).max() / max(np.abs(b).max(), 1e-300))


def test_mollifier_matches_ipctk():
    eps = 1e-3
    y = np.array([0.0, 1e-5, 3e-4, 9.99e-4, 1e-3, 2e-3, 0.5])
    f0, f1 = friction_mollifier(y, eps)
    assert rel(f0, [ipctk.smooth_friction_f0(v, eps) for v in y]) < 1e-14
    assert rel(f1, [ipctk.smooth_friction_f1(v, eps) for v in y]) < 1e-14
    # C1 at eps, f0(0) = eps / 3, f1 <= 1
    a, b = friction_mollifier([eps - 1e-12, eps + 1e-12], eps)
    assert abs(a[0] - a[1]) < 1e-11 and abs(b[0] - b[1]) < 1e-8
    assert f0[0] == pytest.approx(eps / 3) and (f1 <= 1).all()
    # the kernel's f1/y and (f1' y - f1)/y^3, used by the gradient and the Hessian
    for v in y[1:]:
        _, f1y, f2 = _mollifier(v, eps)
        assert f1y == pytest.approx(ipctk.smooth_friction_f1_over_x(v, eps), rel=1e-13)
        assert f2 == pytest.approx(ipctk.smooth_friction_f2_x_minus_f1_over_x3(v, eps), rel=1e-13)


def crossing(z=0.205):
    return np.array([[0, 0, 0], [1, 0, 0], [0.3, -0.5, z], [0.35, 0.5, z + 0.001]])


@pytest.mark.parametrize("scale", [2e-4, 3e-3])      # sticking and sliding
def test_pair_friction_derivatives(scale, rng):
    P = crossing()
    st = pair_stencil(EL2, [0.1, 0.1], [0], [1], degree=np.array([2, 2, 2, 2]))
    lag = pair_friction_lag(P, st, ENF, mu=0.4)
    assert len(lag) == 1 and lag.normal_force[0] > 0
    x = P + rng.normal(scale=scale, size=P.shape)
    ev = friction_potential(lag, x, P, 1e-3, project=False)
    h = 1e-7
    g = np.zeros(12)
    H = np.zeros((12, 12))
    for i in range(12):
        xp, xm = x.ravel().copy(), x.ravel().copy()
        xp[i] += h
        xm[i] -= h
        ep = friction_potential(lag, xp.reshape(4, 3), P, 1e-3, project=False)
        em = friction_potential(lag, xm.reshape(4, 3), P, 1e-3, project=False)
        g[i] = (ep.energy - em.energy) / (2 * h)
        H[i] = (ep.grad.ravel() - em.grad.ravel()) / (2 * h)
    assert rel(ev.grad.ravel(), g) < 1e-6 and rel(ev.hess[0], H) < 1e-5
    assert np.linalg.eigvalsh(ev.hess[0]).min() > -1e-10 * np.abs(ev.hess[0]).max()
    assert np.abs(ev.grad.sum(axis=0)).max() < 1e-14      # action = reaction


def test_near_a_node_the_pair_rubs_with_the_potentials_net_normal_force(rng):
    """Near a node the pair's inclusion-exclusion has negative terms; the pair rubs once, with their
    net (the potential's normal force on the pair), and its Hessian is PSD without projection."""
    P = np.array([[0, 0, 0], [1, 0, 0], [0.97, -0.5, 0.205], [1.02, 0.5, 0.206]])
    st = pair_stencil(EL2, [0.1, 0.1], [0], [1], degree=np.array([2, 2, 2, 2]))
    lag = pair_friction_lag(P, st, ENF, mu=0.4)
    assert lag.lam.shape == (1, 1)
    assert lag.lam[0, 0] == pytest.approx(pair_potential(P, st, ENF, hessian=False).lam[0], rel=1e-12)
    x = P + rng.normal(scale=5e-4, size=P.shape)
    ex, ep = (friction_potential(lag, x, P, 1e-3, project=p) for p in (False, True))
    assert np.array_equal(ex.hess, ep.hess) and ex.energy == ep.energy
    assert np.linalg.eigvalsh(ex.hess[0]).min() > -1e-12 * np.abs(ex.hess[0]).max()


def test_a_patch_shares_its_net_normal_force_among_its_pressing_pairs():
    """Pairs that share a node of either yarn form a patch; a pair whose net is negative corrects its
    neighbours, never rubs the wrong way; separate patches and periodic images stay apart."""
    nodes = np.array([[0, 1, 10, 11], [1, 2, 10, 11], [2, 3, 11, 12], [20, 21, 30, 31], [20, 21, 30, 31]])
    shift = np.zeros((5, 4, 3))
    shift[4, 2:] = [5.0, 0, 0]                       # the same nodes of b, one period over
    lab = contact_patches(nodes, shift)
    assert lab[0] == lab[1] == lab[2] and len({lab[0], lab[3], lab[4]}) == 3
    lam = patch_shares([0.5, -0.2, 0.3, 0.4, -0.1], nodes, shift)
    np.testing.assert_allclose(lam, [0.5 * 0.6 / 0.8, 0.0, 0.3 * 0.6 / 0.8, 0.4, 0.0], rtol=1e-14)


def test_coulomb_force_sliding_and_sticking_on_a_plate():
    x0 = np.array([[0.0, 0.0, 0.105]])
    lag = plate_friction_lag(x0, [0], 0.1, [0, 0, 0], [0, 0, 1], ENF, mu=0.3)
    N = -ENF.energy(0.005)[1]
    assert lag.lam[0, 0] == pytest.approx(N)
    eps = 1e-3
    for s, direction in ((5e-4, (1, 0, 0)), (3e-3, (0.6, 0.8, 0)), (0.05, (0, -1, 0))):
        d = np.asarray(direction, float)
        ev = friction_potential(lag, x0 + s * d, x0, eps)
        F = -ev.grad[0]
        assert abs(F[2]) < 1e-15 and F @ d < 0                 # tangential, against the slip
        assert np.allclose(np.cross(F, d), 0, atol=1e-15)
        if s >= eps:
            assert np.linalg.norm(F) == pytest.approx(0.3 * N, rel=1e-13)
            assert ev.dissipation == pytest.approx(0.3 * N * s, rel=1e-12)       # force x slip
        else:
            assert np.linalg.norm(F) < 0.3 * N
            assert ev.dissipation == pytest.approx(np.linalg.norm(F) * s, rel=1e-12)
        assert np.allclose(ev.plate_force[0], -F)
    # a moving plate: the slip is relative to the plate
    ev = friction_potential(lag, x0 + [0.02, 0, 0], x0, eps, plate_motion=[[0.02, 0, 0]])
    assert ev.dissipation == 0 and np.abs(ev.grad).max() == 0


def test_dissipation_is_the_end_force_times_the_slip():
    """The lagged potential is an implicit-Euler step of a rate-regularised law: its force acts over
    the whole step, so a sliding contact dissipates mu N s for any eps (the work of the regularised
    force along the path would miss mu N eps / 3 every step: 3 % of a thin yarn's slide); a sticking
    one f1(s) mu N s."""
    x0 = np.array([[0.0, 0.0, 0.105]])
    lag = plate_friction_lag(x0, [0], 0.1, [0, 0, 0], [0, 0, 1], ENF, mu=0.25)
    N = lag.lam[0, 0]
    for eps in (1e-2, 1e-3, 1e-4):
        for s in (0.1, 0.5 * eps):
            ev = friction_potential(lag, x0 + [s, 0, 0], x0, eps)
            f1 = friction_mollifier(s, eps)[1]
            assert ev.dissipation == pytest.approx(0.25 * N * f1 * s, rel=1e-12)
            assert np.linalg.norm(ev.grad[0]) == pytest.approx(0.25 * N * f1, rel=1e-12)
        assert friction_mollifier(0.1, eps)[1] == 1.0


def test_energy_does_not_depend_on_the_tangent_basis(rng):
    P = crossing()
    st = pair_stencil(EL2, [0.1, 0.1], [0], [1])
    lag = pair_friction_lag(P, st, ENF, mu=0.4)
    T = lag.basis[0, 0]
    n = np.cross(T[:, 0], T[:, 1])
    # orthonormal tangents, normal along the closest-point direction
    assert np.allclose(T.T @ T, np.eye(2)) and abs(abs(n[2]) - 1) < 1e-3
    x = P + rng.normal(scale=2e-3, size=P.shape)
    e0 = friction_potential(lag, x, P, 1e-3).energy
    a = 0.7
    R = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    lag.basis[0, 0] = T @ R
    assert friction_potential(lag, x, P, 1e-3).energy == pytest.approx(e0, rel=1e-13)


def test_pair_sliding_force_is_mu_lambda():
    """Segment b, pressed on a, slides along it: the friction force on b is mu lambda against
    the slip of the closest points, and a gets the opposite."""
    P = crossing()
    st = pair_stencil(EL2, [0.1, 0.1], [0], [1])
    lag = pair_friction_lag(P, st, ENF, mu=0.4)
    lam = lag.normal_force[0]
    x = P.copy()
    x[2:] += [0.02, 0, 0]
    ev = friction_potential(lag, x, P, 1e-3)
    Fb = -ev.grad[2:].sum(axis=0)
    assert np.allclose(Fb, [-0.4 * lam, 0, 0], rtol=1e-6, atol=1e-12)
    assert np.allclose(-ev.grad[:2].sum(axis=0), -Fb)
    assert ev.dissipation == pytest.approx(0.4 * lam * 0.02, rel=1e-6)


@pytest.mark.parametrize("depth, angle", [(0.05, 90.0), (0.6, 90.0), (0.3, 30.0), (0.6, 12.0), (0.6, 5.0), (0.6, 1.0)])
def test_a_rigid_slide_of_a_thick_yarn_rubs_at_mu_N(depth, angle):
    """A contact over dozens of segment pairs, many of them beside the crossing (their closest points
    at a segment end) or with a negative net: slid rigidly (sliding, |slip| >> eps), the upper yarn
    feels mu N against the slip, N the contact force pressing it, and friction dissipates mu N
    |slip|: exactly where the yarns cross (the friction normal is the lines' common perpendicular),
    within 1 % where they lie near parallel (the rubbing points' normal; docs/contact.md)."""
    x, st, enf = thick_crossing(depth, angle)
    n = len(x) // 2
    N = -pair_potential(x, st, enf, hessian=False).grad[n:, 2].sum()
    lag = pair_friction_lag(x, st, enf, mu=0.3)
    assert N > 0 and len(lag) > 40 and (lag.lam >= 0).all()
    # the patch presses with what the potential gives (its terms' scalar sum against the vertical
    # part of their vector sum: equal where every term pushes vertically)
    assert lag.lam.sum() == pytest.approx(N, rel=1e-3)
    tol = 1e-9 if angle >= 8.0 else 1e-2
    for slide in ([0.05, 0, 0], [0, 0.05, 0], [0.03, -0.04, 0]):
        xs = x.copy()
        xs[n:] += slide
        ev = friction_potential(lag, xs, x, 1e-4)
        F = -ev.grad[n:].sum(axis=0)
        assert np.linalg.norm(F + 0.3 * N * np.array(slide) / 0.05) < tol * 0.3 * N
        assert ev.dissipation == pytest.approx(0.3 * N * 0.05, rel=tol)
        assert np.abs(ev.grad.sum(axis=0)).max() < 1e-12 * N      # action = reaction


def stick_slip_run(mu, N, k_t, du, steps, eps=1e-4):
    """A node pressed on a plate by N and pulled along x by a spring (stiffness k_t) whose anchor
    moves du per step. Each step minimises spring + barrier + lagged friction - work of N by
    Newton with a plate-CCD-capped backtracking line search; returns spring forces, slips, the
    dissipated energy and the node's final x."""
    enf = Enforcement("barrier", ghat=0.01, kappa=1.0)
    # start at the normal equilibrium gap: lambda(g) = N
    lo, hi = 1e-9, 0.01
    for _ in range(200):
        g = 0.5 * (lo + hi)
        lo, hi = (g, hi) if -enf.energy(g)[1] > N else (lo, g)
    x = np.array([[0.0, 0.0, 0.1 + g]])
    plate = dict(nodes=[0], radius=0.1, origin=[0, 0, 0], normal=[0, 0, 1])
    U = 0.0
    forces, slips, dis = [], [], 0.0
    for _ in range(steps):
        U += du
        xs = x.copy()
        lag = plate_friction_lag(xs, enforcement=enf, mu=mu, **plate)

        def total(y, hess=True):
            c = plate_potential(y, enforcement=enf, hessian=hess, **plate)
            f = friction_potential(lag, y, xs, eps, hessian=hess)
            E = 0.5 * k_t * (y[0, 0] - U) ** 2 + N * y[0, 2] + c.energy + f.energy
            gr = c.grad + f.grad + [[k_t * (y[0, 0] - U), 0, N]]
            H = None
            if hess:
                H = np.diag([k_t, 0, 0]) + (c.hess.sum(axis=0) if c.n_active else 0) + f.hess.sum(axis=0)
            return E, gr, H

        for it in range(50):
            E, gr, H = total(x)
            if np.abs(gr).max() < 1e-10 * N:
                break
            dx = -np.linalg.solve(H + 1e-12 * np.eye(3), gr.ravel()).reshape(1, 3)
            a = plate_step_bound(x, dx, eta=0.1, **plate)
            while total(x + a * dx, False)[0] > E + 1e-4 * a * (gr.ravel() @ dx.ravel()) and a > 1e-12:
                a *= 0.5
            x = x + a * dx
        else:
            raise AssertionError("Newton did not converge")
        f = friction_potential(lag, x, xs, eps, hessian=False)
        forces.append(k_t * (U - x[0, 0]))
        slips.append(float(f.slip[0, 0]))
        dis += f.dissipation
    return np.array(forces), np.array(slips), dis, x[0, 0]


def test_pressed_node_sticks_below_mu_n_and_slides_at_it():
    mu, N, k_t, du = 0.3, 0.05, 1.0, 2e-3
    F, slip, dis, xf = stick_slip_run(mu, N, k_t, du, steps=20)
    stick = F < mu * N * (1 - 1e-3)
    assert stick[:5].all() and not stick[-8:].any()          # sticks, then slides
    assert (slip[stick] < 1e-4).all()                        # sticking: below eps
    assert F.max() < mu * N * (1 + 1e-6)                     # never above Coulomb
    assert rel(F[-8:], np.full(8, mu * N)) < 1e-6            # sliding at F = mu N
    # dissipated energy = mu N x total slip, less at most mu N eps / 3 per step (the mollifier)
    assert 0 < mu * N * xf - dis < mu * N * 20 * 1e-4 / 3


def test_friction_coefficient_tables():
    table = [[0.2, 0.4], [0.4, 0.1]]
    assert np.allclose(friction_coefficients(table, [0, 1, 1], [1, 1, 0]), [0.4, 0.1, 0.4])
    assert np.allclose(friction_coefficients(0.3, n=4), 0.3)
    with pytest.raises(InputError, match="symmetric"):
        friction_coefficients([[0.2, 0.3], [0.4, 0.1]], [0], [1])
    with pytest.raises(InputError, match="mu"):
        friction_coefficients(-0.1, n=2)
    with pytest.raises(InputError, match="table"):
        friction_coefficients(table, [0], [2])
    with pytest.raises(InputError, match="eps_v"):
        lag = plate_friction_lag(np.array([[0, 0, 0.105]]), [0], 0.1, [0, 0, 0], [0, 0, 1], ENF, mu=0.3)
        friction_potential(lag, np.zeros((1, 3)), np.zeros((1, 3)), 0.0)
