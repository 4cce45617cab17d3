"""Collision-free step bounds: additive CCD for yarn pairs (crossings in one big step, rotation-like
motions, periodic images, random motions checked by dense sampling and against ipctk), exact plate
bounds (tunnelling), the displacement cap and swept candidates."""

import numpy as np
import pytest

import homtex
from homtex.contact.broad import BroadPhase
from homtex.contact.ccd import displacement_cap, pair_step_bound, plate_step_bound, step_candidates
from homtex.contact.plates import plate_gaps
from homtex.contact.potential import pair_gaps
from homtex.contact.stencil import frame_stencil, pair_stencil
from homtex.errors import InputError
from homtex.model.exclusions import arc_exclusions

ipctk = pytest.importorskip("ipctk")

EL2 = np.array([[0, 1], [2, 3]])


def gaps_along(x, dx, st, alphas):
    return np.array([pair_gaps(x + a * dx, st) for a in alphas])


def test_crossing_in_one_big_step_is_stopped():
    st = pair_stencil(EL2, [0.1, 0.1], [0], [1])
    x = np.array([[0, 0, 0], [1, 0, 0], [0.5, -0.5, 0.3], [0.5, 0.5, 0.3]])
    dx = np.zeros_like(x)
    dx[2:, 2] = -1.0                                  # b passes right through a ...
    assert gaps_along(x, dx, st, [1.0])[0, 0] > 0.4   # ... and ends clear of it: tunnelling
    assert gaps_along(x, dx, st, np.linspace(0, 1, 101))[:, 0].min() < -0.1
    alpha, toi, it = pair_step_bound(x, dx, st, eta=0.1, return_pairs=True)
    assert alpha == pytest.approx(0.09, rel=1e-12)    # head-on: the bound is exact in one advance
    assert pair_gaps(x + alpha * dx, st)[0] == pytest.approx(0.01, rel=1e-9)
    hit, t_ipc = ipctk.AdditiveCCD().edge_edge_ccd(*x, *(x + dx), min_distance=0.2)
    assert hit and alpha <= t_ipc + 1e-12
    # moving apart or sideways far away never limits the step
    assert pair_step_bound(x, -dx, st) == 1.0
    dx2 = np.zeros_like(x)
    dx2[2:, 1] = 5.0
    x2 = x + [0, 0, 1.0] * np.array([[0], [0], [1], [1]])
    assert pair_step_bound(x2, dx2, st) == 1.0


def test_rotation_like_motion_is_safe():
    """b swings 40 degrees about its end b0 and sweeps through a (a large rotation taken as one
    linear step): it starts and ends clear of a."""
    st = pair_stencil(EL2, [0.1, 0.1], [0], [1])
    th = np.radians(40.0)
    x = np.array([[0, 0, 0], [1, 0, 0], [0.5, -1.0, 0.3], [0.5, 1.0, 0.3]])
    dx = np.zeros_like(x)
    dx[3] = [0.5, -1 + 2 * np.cos(th), 0.3 - 2 * np.sin(th)] - x[3]
    g = gaps_along(x, dx, st, np.linspace(0, 1, 2001))[:, 0]
    assert g[0] > 0 and g[-1] > 0 and g.min() < 0          # tunnels through a
    alpha = pair_step_bound(x, dx, st, eta=0.1)
    a = np.linspace(0, alpha, 2001)
    assert gaps_along(x, dx, st, a)[:, 0].min() >= 0.1 * g[0] * (1 - 1e-9)
    first = np.linspace(0, 1, 2001)[np.argmax(g < 0.1 * g[0])]
    assert 0.5 * first < alpha <= first


def test_random_motions_never_miss_and_agree_with_ipctk(rng):
    st = pair_stencil(EL2, [0.05, 0.05], [0], [1])
    ratios, hits = [], 0
    ts = np.linspace(0, 1, 1001)
    for _ in range(150):
        x = rng.normal(size=(4, 3))
        dx = 2 * rng.normal(size=(4, 3))
        g0 = pair_gaps(x, st)[0]
        if g0 <= 0:
            continue
        alpha = pair_step_bound(x, dx, st, eta=0.1)
        g_safe = gaps_along(x, dx, st, np.linspace(0, alpha, 201))[:, 0]
        assert g_safe.min() >= 0.1 * g0 * (1 - 1e-9)            # never below the target
        g = gaps_along(x, dx, st, ts)[:, 0]
        hit, toi = ipctk.TightInclusionCCD().edge_edge_ccd(*x, *(x + dx), min_distance=0.1)
        if g.min() < -1e-3 * g0:     # (ipctk is conservative: it may also report near misses)
            hits += 1
            assert hit and alpha < ts[np.argmax(g < 0)]          # ipctk sees it; we stop before it
        below = np.flatnonzero(g < 0.1 * g0)
        if len(below):
            ratios.append(alpha / ts[below[0]])
        else:
            # stops early only where the gap came within rtol (5 %) of the way to the target
            assert alpha == 1.0 or g.min() <= 0.1 * g0 + 0.05 * 0.9 * g0
    assert hits > 10
    assert min(ratios) > 0.5 and np.median(ratios) > 0.9          # safe, yet not timid


def test_periodic_image_pair():
    period = np.array([[3.0, 0.0, 0.0]])
    st = pair_stencil(EL2, [0.1, 0.1], [0], [1], image=[[1]], periods=period, images=np.zeros((2, 1), int))
    x = np.array([[2.6, 0, 0], [3.4, 0, 0], [0.2, -0.5, 0.3], [0.3, 0.5, 0.3]])
    dx = np.zeros_like(x)
    dx[2:] = [0.05, 0, -0.5]
    xe = x.copy()
    xe[2:] += period[0]
    st_e = pair_stencil(EL2, [0.1, 0.1], [0], [1])
    alpha = pair_step_bound(x, dx, st)
    assert alpha < 1 and alpha == pytest.approx(pair_step_bound(xe, dx, st_e), rel=1e-14)
    assert pair_gaps(x + alpha * dx, st)[0] >= 0.1 * pair_gaps(x, st)[0] * (1 - 1e-9)


def test_plate_tunnelling_bound_is_exact():
    x = np.array([[0.0, 0.0, 0.2], [1.0, 0.0, 0.15], [2.0, 0.0, 0.5]])
    dx = np.array([[0.0, 0.0, -1.0], [0.3, 0.0, -0.5], [0.0, 0.0, 1.0]])   # nodes 0, 1 tunnel
    kw = dict(nodes=[0, 1, 2], radius=0.1, origin=[0, 0, 0], normal=[0, 0, 1])
    alpha, t = plate_step_bound(x, dx, eta=0.1, return_nodes=True, **kw)
    assert np.allclose(t, [0.9 * 0.1 / 1.0, 0.9 * 0.05 / 0.5, 1.0])
    assert alpha == pytest.approx(0.09)
    assert plate_gaps(x + alpha * dx, **kw)[0] == pytest.approx(0.01)
    hit, toi = ipctk.point_static_plane_ccd(x[0], x[0] + dx[0], np.array([0, 0, 0.1]), np.array([0, 0, 1.0]),
                                            conservative_rescaling=1.0)
    assert hit and alpha < toi
    # a plate moving down onto resting nodes limits the step the same way
    a2 = plate_step_bound(x, np.zeros_like(x), plate_motion=[[0, 0, 1.0]], eta=0.1, **kw)
    assert a2 == pytest.approx(0.9 * 0.05)


def test_displacement_cap_is_blind_to_gaps():
    st = pair_stencil(EL2, [0.1, 0.1], [0], [1])
    x = np.array([[0, 0, 0], [1, 0, 0], [0.5, -0.5, 0.22], [0.5, 0.5, 0.22]])
    dx = np.zeros_like(x)
    dx[:2, 2] = 0.1
    dx[2:, 2] = -0.1                                   # head-on, each node moves r_min
    assert displacement_cap(dx, 0.1) == 1.0
    assert pair_gaps(x + dx, st)[0] < 0               # the cap lets the pair overlap ...
    assert pair_step_bound(x, dx, st) == pytest.approx(0.09)   # ... the CCD does not
    assert displacement_cap(10 * dx, 0.1) == pytest.approx(0.1)
    with pytest.raises(InputError, match="r_min"):
        displacement_cap(dx, 0.0)


def test_swept_candidates_find_pairs_reached_during_the_step():
    n = 6
    X = np.vstack([np.column_stack([np.linspace(0, 2, n), np.zeros(n), np.zeros(n)]),
                   np.column_stack([np.full(n, 1.1), np.linspace(-1, 1, n), np.full(n, 0.8)])])
    el = np.vstack([np.column_stack([np.arange(n - 1), np.arange(1, n)]),
                    np.column_stack([n + np.arange(n - 1), n + np.arange(1, n)])])
    fr = homtex.Frame(X, el, radius=0.1, E=1000.0, nu=0.3, yarn=np.repeat([0, 1], n - 1))
    bp = BroadPhase(fr.elements, fr.contact_radius, exclusions=arc_exclusions(fr))
    dx = np.zeros_like(X)
    dx[n:, 2] = -1.0                                   # yarn 1 falls through yarn 0
    assert len(bp.pairs(X, 0.01)["a"]) == 0
    st = frame_stencil(fr, step_candidates(bp, X, dx, ghat=0.01))
    assert len(st) > 0
    alpha = pair_step_bound(X, dx, st)
    assert alpha == pytest.approx(0.9 * 0.6, rel=1e-9)


def test_ccd_inputs_are_checked():
    st = pair_stencil(EL2, [0.1, 0.1], [0], [1])
    x = np.zeros((4, 3))
    x[1, 0] = x[3, 1] = 1
    x[2:, 2] = 1
    with pytest.raises(InputError, match="eta"):
        pair_step_bound(x, np.zeros((4, 3)), st, eta=1.0)
    with pytest.raises(InputError, match="dx"):
        pair_step_bound(x, np.zeros((3, 3)), st)
