"""Large-motion contact: distances against ipctk and finite differences, enforcement functions,
the batched pair/plate potentials (derivatives, invariances, no node double counting, the
near-parallel blend, periodic images) and the arc-length same-yarn filter."""

import numpy as np
import pytest

import homtex
from homtex.contact.broad import BroadPhase, exclusion_lists
from homtex.contact.distance import (
    point_plane_gap,
    point_point_distance,
    point_segment_distance,
    segment_distance,
    sin2_angle,
)
from homtex.contact.plates import plate_potential
from homtex.contact.potential import Enforcement, assemble_blocks, pair_potential
from homtex.contact.stencil import frame_stencil, pair_stencil
from homtex.errors import InputError
from homtex.knits.relax import FILAMENT_SAGITTA, knit_contact
from homtex.model.exclusions import arc_exclusions

ipctk = pytest.importorskip("ipctk")


def rel(a, b):
    a, b = np.asarray(a, float), np.asarray(b, float)
    return float(np.abs(a - b).max() / max(np.abs(b).max(), 1e-300))


def fd_grad_hess(fun, x, h):
    """Central differences of fun(x) -> (value, grad) over the flat x."""
    x = np.asarray(x, float).ravel()
    g = np.zeros(x.size)
    H = np.zeros((x.size, x.size))
    for i in range(x.size):
        xp, xm = x.copy(), x.copy()
        xp[i] += h
        xm[i] -= h
        fp, gp = fun(xp)
        fm, gm = fun(xm)
        g[i] = (fp - fm) / (2 * h)
        H[i] = (gp - gm) / (2 * h)
    return g, H


# ----------------------------------------------------------------------------------------
# distances
def test_segment_distance_matches_ipctk_on_random_pairs(rng):
    seen = set()
    for _ in range(400):
        P = rng.normal(size=(4, 3))
        d2, g, H, case = segment_distance(*P)
        assert case == int(ipctk.edge_edge_distance_type(*P))
        seen.add(case)
        assert d2 == pytest.approx(ipctk.edge_edge_distance(*P), rel=1e-11)
        assert rel(g, ipctk.edge_edge_distance_gradient(*P)) < 1e-10
        assert rel(H, ipctk.edge_edge_distance_hessian(*P)) < 1e-10
    assert seen == set(range(9))            # every closest-point case was exercised


def test_point_segment_and_point_point_match_ipctk(rng):
    for _ in range(200):
        p, e0, e1 = rng.normal(size=(3, 3))
        d2, g, H, case = point_segment_distance(p, e0, e1)
        assert case == int(ipctk.point_edge_distance_type(p, e0, e1))
        assert d2 == pytest.approx(ipctk.point_edge_distance(p, e0, e1), rel=1e-12)
        assert rel(g, ipctk.point_edge_distance_gradient(p, e0, e1)) < 1e-11
        assert rel(H, ipctk.point_edge_distance_hessian(p, e0, e1)) < 1e-11
    p, q = rng.normal(size=(2, 3))
    d2, g, H = point_point_distance(p, q)
    assert d2 == pytest.approx(ipctk.point_point_distance(p, q), rel=1e-14)
    assert rel(g, ipctk.point_point_distance_gradient(p, q)) < 1e-14
    assert rel(H, ipctk.point_point_distance_hessian(p, q)) < 1e-14


@pytest.mark.parametrize("name,P", [
    ("parallel overlapping", [[0, 0, 0], [2, 0, 0], [0.5, 0.3, 0.1], [3, 0.3, 0.1]]),
    ("parallel disjoint", [[0, 0, 0], [1, 0, 0], [1.5, 0.2, 0], [3, 0.2, 0]]),
    ("antiparallel", [[0, 0, 0], [1, 0, 0], [1.2, 0, 0.3], [-0.4, 0, 0.3]]),
    ("collinear end-on", [[0, 0, 0], [1, 0, 0], [1.3, 0, 0], [2, 0, 0]]),
    ("crossing, touching", [[0, 0, 0], [1, 0, 0], [0.5, -1, 0], [0.5, 1, 0]]),
    ("T, end on interior", [[0, 0, 0], [1, 0, 0], [0.5, 0, 0.4], [0.5, 0, 2]]),
    ("nearly parallel", [[0, 0, 0], [1, 0, 0], [0.2, 0.3, 0], [1.2, 0.3 + 1e-7, 1e-7]]),
])
def test_segment_distance_degenerate_configurations(name, P):
    P = np.asarray(P, float)
    d2, g, H, case = segment_distance(*P)
    assert d2 == pytest.approx(ipctk.edge_edge_distance(*P), rel=1e-9, abs=1e-14)
    # the squared distance is the minimum over the segments: never above any end-segment distance
    ends = [point_segment_distance(P[0], P[2], P[3])[0], point_segment_distance(P[1], P[2], P[3])[0],
            point_segment_distance(P[2], P[0], P[1])[0], point_segment_distance(P[3], P[0], P[1])[0]]
    assert d2 <= min(ends) + 1e-14
    # brute force over a fine parameter grid
    s = np.linspace(0, 1, 801)
    A = P[0] + s[:, None] * (P[1] - P[0])
    B = P[2] + s[:, None] * (P[3] - P[2])
    brute = ((A[:, None] - B[None]) ** 2).sum(-1).min()
    assert d2 <= brute + 1e-12 and brute - d2 < 1e-5
    assert np.isfinite(g).all() and np.isfinite(H).all()


def test_distance_invariances(rng):
    from scipy.spatial.transform import Rotation
    for _ in range(20):
        P = rng.normal(size=(4, 3))
        d2, g, H, case = segment_distance(*P)
        R = Rotation.random(random_state=int(rng.integers(1 << 30))).as_matrix()
        Q = P @ R.T + rng.normal(size=3)
        d2q, gq, Hq, caseq = segment_distance(*Q)
        assert d2q == pytest.approx(d2, rel=1e-11) and caseq == case
        Rb = np.kron(np.eye(4), R)
        assert rel(gq, Rb @ g) < 1e-10 and rel(Hq, Rb @ H @ Rb.T) < 1e-10
        # swapping the pair and reversing a segment permute the derivatives
        d2s, gs, Hs, _ = segment_distance(P[2], P[3], P[0], P[1])
        perm = np.r_[6:12, 0:6]
        assert d2s == pytest.approx(d2, rel=1e-12)
        assert rel(gs, g[perm]) < 1e-11 and rel(Hs, H[np.ix_(perm, perm)]) < 1e-11
        d2r, gr, _, _ = segment_distance(P[1], P[0], P[2], P[3])
        perm = np.r_[3:6, 0:3, 6:12]
        assert d2r == pytest.approx(d2, rel=1e-12) and rel(gr, g[perm]) < 1e-11


def test_sin2_angle_derivatives(rng):
    for _ in range(5):
        P = rng.normal(size=(4, 3))
        c, g, H = sin2_angle(*P)
        ea, eb = P[1] - P[0], P[3] - P[2]
        assert c == pytest.approx(ipctk.edge_edge_cross_squarednorm(*P) / (ea @ ea * (eb @ eb)), rel=1e-12)
        gf, Hf = fd_grad_hess(lambda x: sin2_angle(*x.reshape(4, 3))[:2], P, 1e-6)
        assert rel(g, gf) < 1e-8 and rel(H, Hf) < 1e-7


def test_point_plane_gap_matches_ipctk(rng):
    p, o = rng.normal(size=(2, 3))
    n = rng.normal(size=3)
    g, grad = point_plane_gap(p, o, n, radius=0.1)
    assert (g + 0.1) ** 2 == pytest.approx(ipctk.point_plane_distance(p, o, n / np.linalg.norm(n)), rel=1e-12)
    assert rel(grad, n / np.linalg.norm(n)) < 1e-15


def test_distance_inputs_are_checked():
    with pytest.raises(InputError, match="a0"):
        segment_distance([0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0])
    with pytest.raises(InputError, match="zero length"):
        segment_distance([0, 0, 0], [0, 0, 0], [0, 1, 0], [1, 1, 0])
    with pytest.raises(InputError, match="finite"):
        point_segment_distance([np.nan, 0, 0], [0, 0, 0], [1, 0, 0])
    with pytest.raises(InputError, match="radius"):
        point_plane_gap([0, 0, 1], [0, 0, 0], [0, 0, 1], radius=-1)


# ----------------------------------------------------------------------------------------
# enforcement functions
def test_barrier_matches_ipctk_and_is_c2():
    enf = Enforcement("barrier", ghat=0.3, kappa=2.5)
    g = np.linspace(0.01, 0.29, 15)
    e, e1, e2 = enf.energy(g)
    ref = [[ipctk.barrier(v, 0.3), ipctk.barrier_first_derivative(v, 0.3), ipctk.barrier_second_derivative(v, 0.3)]
           for v in g]
    assert rel(np.column_stack([e, e1, e2]), 2.5 * np.array(ref)) < 1e-12
    e, e1, e2 = enf.energy([0.3 - 1e-9, 0.3, 1.0])
    assert np.abs([e, e1]).max() < 1e-15 and np.abs(e2).max() < 1e-7      # C2 at ghat (e2 ~ ghat - g)
    assert np.isinf(enf.energy(0.0)[0]) and np.isinf(enf.energy(-0.1)[0])


@pytest.mark.parametrize("kind", ["barrier", "penalty", "cubic"])
def test_enforcement_derivatives_by_finite_differences(kind):
    enf = Enforcement(kind, ghat=0.2, kappa=3.0)
    g = np.array([0.013, 0.07, 0.15, 0.199] + ([-0.05, -1e-3, 1e-3] if kind != "barrier" else []))
    h = 1e-7
    e, e1, e2 = enf.energy(g)
    assert rel(e1, (enf.energy(g + h)[0] - enf.energy(g - h)[0]) / (2 * h)) < 1e-7
    assert rel(e2, (enf.energy(g + h)[1] - enf.energy(g - h)[1]) / (2 * h)) < 1e-6
    assert (e >= 0).all() and (e1 <= 0).all() and (e2 >= 0).all()    # repulsive, convex


def test_penalty_is_a_shifted_linear_penalty_beyond_contact():
    enf = Enforcement("penalty", ghat=0.02, kappa=500.0)
    g = np.array([-0.3, -0.01, 0.0])
    e, e1, e2 = enf.energy(g)
    assert np.allclose(-e1, 500.0 * (0.01 - g)) and np.allclose(e2, 500.0)
    e, e1, e2 = enf.energy([-1e-12, 1e-12])           # C2 at g = 0
    assert abs(e[0] - e[1]) < 1e-10 and abs(e1[0] - e1[1]) < 1e-8 and abs(e2[0] - e2[1]) < 1e-6


def test_enforcement_rejects_bad_parameters():
    with pytest.raises(InputError, match="kind"):
        Enforcement("lagrange")
    with pytest.raises(InputError, match="ghat"):
        Enforcement(ghat=0.0)
    with pytest.raises(InputError, match="kappa"):
        Enforcement(kappa=np.nan)
    with pytest.raises(InputError, match="parallel_deg"):
        Enforcement(parallel_deg=(3.0, 2.0))


# ----------------------------------------------------------------------------------------
# pair potential
EL2 = np.array([[0, 1], [2, 3]])


def one_pair(deg=(2, 2, 2, 2), r=0.1):
    return pair_stencil(EL2, [r, r], [0], [1], degree=np.array(deg))


def energy_grad(st, enf):
    def fun(x):
        ev = pair_potential(x.reshape(-1, 3), st, enf)
        return ev.energy, ev.grad.ravel()
    return fun


def tilted(angle_deg, z=0.21, x0=0.3, lift=0.1):
    th = np.radians(angle_deg)
    b1 = [x0 + np.cos(th), 0.7 * np.sin(th), z + lift * 0.7 * np.sin(th)]
    return np.array([[0, 0, 0], [1, 0, 0], [x0, 0, z], b1])


@pytest.mark.parametrize("kind,kappa,h", [("penalty", 100.0, 1e-6), ("barrier", 1.0, 1e-7)])
@pytest.mark.parametrize("label,P,deg", [
    ("crossing", [[0, 0, 0], [1, 0, 0], [0.3, -0.5, 0.205], [0.35, 0.5, 0.215]], (2, 2, 2, 2)),
    ("crossing near a node", [[0, 0, 0], [1, 0, 0], [0.98, -0.5, 0.21], [1.03, 0.5, 0.215]], (2, 2, 2, 2)),
    ("yarn ends", [[0, 0, 0], [1, 0, 0], [0.98, -0.5, 0.21], [1.03, 0.5, 0.215]], (1, 2, 3, 1)),
    ("parallel form", tilted(0.5), (2, 2, 2, 2)),
    ("blend zone", tilted(1.6), (2, 2, 2, 2)),
])
def test_pair_potential_derivatives(kind, kappa, h, label, P, deg):
    enf = Enforcement(kind, ghat=0.05, kappa=kappa, project=False)
    P = np.asarray(P, float)
    st = one_pair(deg)
    ev = pair_potential(P, st, enf)
    assert ev.n_active == 1 and ev.energy > 0
    g, H = fd_grad_hess(energy_grad(st, enf), P, h)
    assert rel(ev.grad.ravel(), g) < 1e-6
    assert rel(ev.hess[0], H) < 1e-5
    assert np.allclose(ev.hess[0], ev.hess[0].T, atol=1e-12 * np.abs(ev.hess[0]).max())
    assert np.abs(ev.grad.sum(axis=0)).max() < 1e-12 * np.abs(ev.grad).max()     # no net force


def test_projected_hessian_is_the_eigen_projection(rng):
    """Blocks are projected to PSD by clamping eigenvalues: the reduced projection of single-term
    pairs (<= 5-dimensional) and the full 12 x 12 one agree with numpy's eigendecomposition."""
    enf = Enforcement("barrier", ghat=0.05, kappa=1.0, project=True)
    enf_raw = Enforcement("barrier", ghat=0.05, kappa=1.0, project=False)
    st = one_pair()
    n_indef = 0
    for k in range(40):
        P = np.array([[0, 0, 0], [1, 0, 0], [0.5, -0.5, 0.22], [0.5, 0.5, 0.22]])
        P += rng.normal(scale=0.05, size=(4, 3))
        if k % 2:       # near a node: several terms (inclusion-exclusion)
            P[2:, 0] += 0.45
        if pair_potential(P, st, enf_raw).n_active == 0:
            continue
        Hp = pair_potential(P, st, enf).hess[0]
        Hr = pair_potential(P, st, enf_raw).hess[0]
        lam, V = np.linalg.eigh(Hr)
        ref = (V * np.maximum(lam, 0)) @ V.T
        assert rel(Hp, ref) < 1e-10
        assert np.linalg.eigvalsh(Hp).min() >= -1e-10 * np.abs(lam).max()
        n_indef += lam.min() < 0
    assert n_indef > 10      # the raw blocks are indefinite in general: the projection matters


def test_pair_energy_is_invariant(rng):
    from scipy.spatial.transform import Rotation
    enf = Enforcement("penalty", ghat=0.05, kappa=10.0)
    P = np.array([[0, 0, 0], [1, 0, 0], [0.3, -0.5, 0.205], [0.35, 0.5, 0.215]])
    st = one_pair((2, 1, 3, 2))
    E = pair_potential(P, st, enf).energy
    R = Rotation.random(random_state=3).as_matrix()
    assert pair_potential(P @ R.T + [5, -2, 1], st, enf).energy == pytest.approx(E, rel=1e-11)
    # swapping a and b (with their node weights) changes nothing
    st_sw = pair_stencil(EL2, [0.1, 0.1], [1], [0], degree=np.array([2, 1, 3, 2]))
    assert pair_potential(P, st_sw, enf).energy == pytest.approx(E, rel=1e-12)


def chain_pair_stencil(XA, XB, r=0.1):
    na, nb = len(XA), len(XB)
    el = np.array([[i, i + 1] for i in range(na - 1)] + [[na + i, na + i + 1] for i in range(nb - 1)])
    A, B = np.meshgrid(np.arange(na - 1), np.arange(na - 1, na + nb - 2), indexing="ij")
    return np.vstack([XA, XB]), pair_stencil(el, np.full(len(el), r), A.ravel(), B.ravel())


@pytest.mark.parametrize("angle", [90.0, 30.0, 6.0])
def test_crossing_counts_once_while_sliding_past_nodes(angle):
    """Yarn B crossing a straight chain A slides along it: the energy stays that of one contact.

    A plain sum over segment pairs would count the contact twice at A's nodes (and four times
    at node-node crossings)."""
    enf = Enforcement("barrier", ghat=0.01, kappa=1.0)
    XA = np.column_stack([np.linspace(0, 3, 11), np.zeros(11), np.zeros(11)])
    th = np.radians(angle)
    gap = 0.004
    E = []
    for xc in np.linspace(1.0, 1.6, 41):       # passes A's nodes at 1.2 and 1.5
        XB = np.array([xc, 0, 0.2 + gap]) + np.linspace(-1, 1, 9)[:, None] * [np.cos(th), np.sin(th), 0]
        x, st = chain_pair_stencil(XA, XB)
        ev = pair_potential(x, st, enf)
        E.append(ev.energy)
        assert -ev.grad[11:, 2].sum() == pytest.approx(-enf.energy(gap)[1], rel=1e-9)
    assert rel(E, np.full(len(E), enf.energy(gap)[0])) < 1e-10


def test_parallel_transition_is_continuous():
    """Rotating a chain through the parallel blend: energy and force change smoothly and the
    energy's rate equals the torque of the forces (no jump hidden between samples)."""
    enf = Enforcement("barrier", ghat=0.01, kappa=1.0)
    XA = np.column_stack([np.linspace(0, 3, 11), np.zeros(11), np.zeros(11)])
    c = np.array([1.45, 0.0, 0.204])
    t = np.linspace(-1, 1, 9)[:, None]

    def state(deg):
        th = np.radians(deg)
        x, st = chain_pair_stencil(XA, c + t * [np.cos(th), np.sin(th), 0])
        ev = pair_potential(x, st, enf, hessian=False)
        torque = np.cross(x[11:] - c, -ev.grad[11:])[:, 2].sum()
        return ev.energy, -ev.grad[11:, 2].sum(), torque

    angles = np.linspace(0.0, 2.5, 251)
    E, F, M = np.array([state(a) for a in angles]).T
    dth = np.radians(angles[1] - angles[0])
    scale = np.abs(np.diff(E)).max()
    assert scale < 0.05 * E.max()                          # no jump: increments stay small
    assert np.abs(np.diff(F)).max() < 0.05 * np.abs(F).max()
    # dE/dtheta = -torque of the contact forces on B (central differences)
    assert rel(-(E[2:] - E[:-2]) / (2 * dth), M[1:-1]) < 0.02
    assert E[0] > 5 * E[-1]                     # the parallel form carries the line contact


@pytest.mark.parametrize("deg", [0.2, 0.45, 0.9])
def test_thin_filaments_crossing_nearly_parallel_see_the_barrier(deg):
    """Two filaments (r = 8.5 um) on 0.2 mm elements crossing at their middles at under a degree:
    their end points, where the nodal (parallel) form looks, are farther apart than the crossing
    by the sagitta (L sin theta)^2 / (8 r_sum), about ghat at 0.9 deg. With the elements' lengths
    (the per-pair blend angles) the energy at the crossing is at least the barrier's at
    parallel_sagitta x ghat in the nodal form (0.2 deg), the blend (0.45) and the crossing form
    (0.9); with the global angles the 0.9 deg crossing is almost invisible (a 3-filament jersey
    stalled on it: the collision check stopped what the potential did not push apart)."""
    L, r, ghat = 0.2, 0.0085, 8.5e-5
    enf = Enforcement("barrier", ghat=ghat, kappa=1.0)
    th = np.radians(deg)
    u = np.array([np.cos(th), np.sin(th), 0.0])
    up = np.array([0.0, 0.0, 2 * r + 1e-3 * ghat])          # 1e-3 ghat apart at the crossing
    x = np.array([[-L / 2, 0, 0], [L / 2, 0, 0], -L / 2 * u + up, L / 2 * u + up])
    el, rad = [[0, 1], [2, 3]], np.full(2, r)
    per_pair = pair_stencil(el, rad, [0], [1], length=np.full(2, L))
    c0, c1 = enf.pair_c_range(per_pair)
    assert c0[0] < enf.c_range[0] and c1[0] / c0[0] == pytest.approx(enf.c_range[1] / enf.c_range[0])
    E = float(pair_potential(x, per_pair, enf, hessian=False).energy)
    assert E >= enf.energy(enf.parallel_sagitta * ghat)[0]
    if deg == 0.9:
        E_global = float(pair_potential(x, pair_stencil(el, rad, [0], [1]), enf, hessian=False).energy)
        assert E_global < 0.01 * E            # a 300th


def test_a_bundles_contact_pushes_a_closing_crossing_apart_with_the_barriers_force():
    """Two filaments (r = 8.5 um, 0.2 mm elements) crossing at 0.45 deg, 1e-3 ghat apart at the
    crossing. With the default parallel_sagitta (0.3) the pair is in the nodal form, which looks at
    the ends, 0.21 ghat apart: it pushes with about 4 |b'(0.21 ghat)| (22 kappa ghat), whatever the
    crossing's gap, so a line load above that closes the crossing against the collision check and
    Newton stalls (a 3-filament jersey at its lock-up). A yarn of filaments in a knit gets
    FILAMENT_SAGITTA (0.01): the pair is in the crossing form and pushes with exactly the barrier's
    force at the crossing's gap, -b'(1e-3 ghat) (about 1000 kappa ghat)."""
    L, r, ghat, kappa = 0.2, 0.0085, 8.5e-5, 1.0
    th, g = np.radians(0.45), 1e-3 * ghat
    u = np.array([np.cos(th), np.sin(th), 0.0])
    up = np.array([0.0, 0.0, 2 * r + g])
    x = np.array([[-L / 2, 0, 0], [L / 2, 0, 0], -L / 2 * u + up, L / 2 * u + up])
    st = pair_stencil([[0, 1], [2, 3]], np.full(2, r), [0], [1], length=np.full(2, L))
    push = {}
    for s in (0.3, FILAMENT_SAGITTA):
        ce = pair_potential(x, st, Enforcement("barrier", ghat=ghat, kappa=kappa, parallel_sagitta=s), hessian=False)
        push[s] = -float(ce.grad[2:4, 2].sum())          # z force on the upper filament, N
    exact = -float(Enforcement("barrier", ghat=ghat, kappa=kappa).energy(g)[1])
    assert push[FILAMENT_SAGITTA] == pytest.approx(exact, rel=1e-6)
    assert exact > 900 * kappa * ghat
    assert 0 < push[0.3] < 30 * kappa * ghat
    info = {"yarn_model": {"model": "filaments", "filaments": 3}, "compression": None}
    assert knit_contact(info, 0.0).parallel_sagitta == FILAMENT_SAGITTA
    info["yarn_model"]["model"] = "equivalent"
    assert knit_contact(info, 0.0).parallel_sagitta == homtex.Contact().parallel_sagitta == 0.3


def test_per_pair_blend_angles_stay_global_for_short_elements():
    """Elements a few radii long (every shipped equivalent-yarn cell): the per-pair angles are the
    global ones, so those models are unchanged."""
    enf = Enforcement("barrier", ghat=0.01 * 0.04, kappa=1.0)
    st = pair_stencil([[0, 1], [2, 3]], np.full(2, 0.04), [0], [1], length=np.full(2, 0.2))
    c0, c1 = enf.pair_c_range(st)
    assert (c0[0], c1[0]) == enf.c_range
    with pytest.raises(InputError, match="length"):
        pair_stencil([[0, 1], [2, 3]], np.full(2, 0.04), [0], [1], length=np.array([0.2, -1.0]))
    with pytest.raises(InputError, match="parallel_sagitta"):
        Enforcement(parallel_sagitta=0.0)


def test_periodic_image_pair_equals_explicit_copy():
    enf = Enforcement("penalty", ghat=0.05, kappa=50.0)
    period = np.array([[3.0, 0.0, 0.0]])
    x = np.array([[2.6, 0, 0], [3.4, 0, 0], [0.2, -0.5, 0.21], [0.3, 0.5, 0.21]])
    # element 0 joins node 0 to node 1, element 1 joins 2 -> 3; b is placed one period on
    st = pair_stencil(EL2, [0.1, 0.1], [0], [1], image=[[1]], periods=period, images=np.zeros((2, 1), int))
    xe = x.copy()
    xe[2:] += period[0]
    st_e = pair_stencil(EL2, [0.1, 0.1], [0], [1])
    ev, ee = pair_potential(x, st, enf), pair_potential(xe, st_e, enf)
    assert ev.n_active == 1
    assert ev.energy == pytest.approx(ee.energy, rel=1e-13)
    assert rel(ev.grad, ee.grad) < 1e-12 and rel(ev.hess, ee.hess) < 1e-12


def test_batched_equals_sum_of_pairs_and_assembles_to_the_hessian(rng):
    enf = Enforcement("penalty", ghat=0.1, kappa=20.0, project=False)
    n_yarn, n_node = 4, 6
    x = []
    for k in range(n_yarn):   # a small crossing grid
        s = np.linspace(0, 2, n_node)
        x.append(np.column_stack([s, np.full(n_node, 0.5 * k), np.full(n_node, 0.0)]) if k % 2 == 0
                 else np.column_stack([np.full(n_node, 0.4 * k), s - 0.5, np.full(n_node, 0.19)]))
    x = np.vstack(x) + rng.normal(scale=0.005, size=(n_yarn * n_node, 3))
    el = np.array([[k * n_node + i, k * n_node + i + 1] for k in range(n_yarn) for i in range(n_node - 1)])
    yarn = np.repeat(np.arange(n_yarn), n_node - 1)
    a, b = np.triu_indices(len(el), 1)
    keep = yarn[a] != yarn[b]
    st = pair_stencil(el, np.full(len(el), 0.1), a[keep], b[keep])
    ev = pair_potential(x, st, enf)
    assert ev.n_active >= 4
    one = [pair_potential(x, pair_stencil(el, np.full(len(el), 0.1), [p], [q]), enf).energy
           for p, q in zip(a[keep], b[keep])]
    assert ev.energy == pytest.approx(sum(one), rel=1e-12)
    K = assemble_blocks(ev.hess, ev.hess_nodes, len(x)).toarray()
    g, H = fd_grad_hess(energy_grad(st, enf), x, 1e-6)
    assert rel(ev.grad.ravel(), g) < 1e-6 and rel(K, H) < 1e-5
    K6 = assemble_blocks(ev.hess, ev.hess_nodes, len(x), dof_per_node=6).toarray()
    tr = (6 * np.arange(len(x))[:, None] + np.arange(3)).ravel()
    assert rel(K6[np.ix_(tr, tr)], K) < 1e-15 and np.abs(K6).sum() == pytest.approx(np.abs(K).sum())


def test_barrier_is_infinite_when_a_pair_touches():
    st = one_pair()
    P = np.array([[0, 0, 0], [1, 0, 0], [0.5, -0.5, 0.19], [0.5, 0.5, 0.19]])
    assert np.isinf(pair_potential(P, st, Enforcement("barrier", ghat=0.05)).energy)
    ev = pair_potential(P, st, Enforcement("penalty", ghat=0.05, kappa=10.0))
    assert np.isfinite(ev.energy) and ev.min_gap == pytest.approx(-0.01) and ev.lam[0] > 0


def test_pair_potential_inputs_are_checked():
    st = one_pair()
    with pytest.raises(InputError, match="x"):
        pair_potential(np.zeros((4, 2)), st, Enforcement())
    with pytest.raises(InputError, match="node 3"):
        pair_potential(np.zeros((3, 3)), st, Enforcement())
    with pytest.raises(InputError, match="radius"):
        pair_stencil(EL2, [0.1, -0.1], [0], [1])


# ----------------------------------------------------------------------------------------
# plates
def test_plate_potential_forces_and_derivatives():
    enf = Enforcement("barrier", ghat=0.02, kappa=5.0)
    x = np.array([[0, 0, 0.105], [1, 0, 0.11], [2, 0, 0.5], [0, 0, 0.895]])
    origin = [[0, 0, 0], [0, 0, 1.0]]
    normal = [[0, 0, 1], [0, 0, -1]]
    ev = plate_potential(x, [0, 1, 2, 3], 0.1, origin, normal, enf, plate=[0, 0, 0, 1])
    assert np.allclose(ev.gap, [0.005, 0.01, 0.4, 0.005]) and list(ev.active) == [0, 1, 3]
    lam = -enf.energy(np.array([0.005, 0.01]))[1]
    assert np.allclose(-ev.grad[:2, 2], lam) and ev.grad[3, 2] == pytest.approx(lam[0])
    assert np.allclose(ev.plate_force[0], [0, 0, -lam.sum()]) and np.allclose(ev.plate_force[1], [0, 0, lam[0]])
    assert np.allclose(ev.lam[[0, 1, 3]], [lam[0], lam[1], lam[0]])

    def fun(xf):
        e = plate_potential(xf.reshape(-1, 3), [0, 1, 2, 3], 0.1, origin, normal, enf, plate=[0, 0, 0, 1])
        return e.energy, e.grad.ravel()
    g, H = fd_grad_hess(fun, x, 1e-8)
    K = assemble_blocks(ev.hess, ev.hess_nodes, 4).toarray()
    assert rel(ev.grad.ravel(), g) < 1e-6 and rel(K, H) < 1e-5


def test_plate_inputs_are_checked():
    with pytest.raises(InputError, match="normal"):
        plate_potential(np.zeros((2, 3)), [0], 0.1, [0, 0, 0], [0, 0, 0], Enforcement())
    with pytest.raises(InputError, match="plate"):
        plate_potential(np.zeros((2, 3)), [0], 0.1, [0, 0, 0], [0, 0, 1], Enforcement(), plate=1)


# ----------------------------------------------------------------------------------------
# same-yarn filter
def helix_frame(pitch, r=0.1, turns=3, n=360):
    t = np.linspace(0, turns * 2 * np.pi, n)
    X = np.column_stack([np.cos(t), np.sin(t), pitch * t / (2 * np.pi)])
    el = np.column_stack([np.arange(n - 1), np.arange(1, n)])
    return homtex.Frame(X, el, radius=r, E=1000.0, nu=0.3)


def test_arc_filter_removes_neighbours_and_keeps_real_self_contact():
    """A helix of short elements (0.05 mm, r = 0.1 mm) whose turns touch (pitch 2r + 5 um).

    Hop-based exclusions leave neighbours a few elements apart inside the contact distance;
    the arc-length filter keeps exactly the turn-to-turn contacts."""
    fr = helix_frame(0.205)
    ghat = 0.01
    for ex, spurious in ((exclusion_lists(fr, 1), True), (arc_exclusions(fr), False)):
        p = BroadPhase(fr.elements, fr.contact_radius, exclusions=ex).pairs(fr.nodes, ghat)
        sep = np.abs(p["a"] - p["b"])
        near = sep < 100                       # one turn is ~120 elements
        assert near.any() == spurious
        if not spurious:
            assert len(p["a"]) > 200 and p["dist"].min() < 0.2051   # the turns' contacts
    # without touching turns nothing is left
    fr = helix_frame(0.4)
    p = BroadPhase(fr.elements, fr.contact_radius, exclusions=arc_exclusions(fr)).pairs(fr.nodes, ghat)
    assert len(p["a"]) == 0


def test_arc_filter_periodic_and_symmetric():
    n, P, r = 40, 4.0, 0.1
    X = np.column_stack([np.linspace(0, P, n, endpoint=False), np.zeros(n), np.zeros(n)])
    el = np.column_stack([np.arange(n), (np.arange(n) + 1) % n])
    img = np.zeros((n, 1), int)
    img[-1] = 1
    fr = homtex.Frame(X, el, radius=r, E=1000.0, nu=0.3, periods=[[P, 0, 0]], images=img)
    ptr, e, i = arc_exclusions(fr, margin=0.1)
    # element 0 excludes 1, 2, 3 ahead and 39, 38, 37 behind (one period back): ell = 0, 0.1, 0.2
    assert sorted(zip(e[ptr[0]:ptr[1]], i[ptr[0]:ptr[1], 0])) == [(1, 0), (2, 0), (3, 0), (37, -1), (38, -1), (39, -1)]
    pairs = {(a, int(b), int(im)) for a in range(n) for b, im in zip(e[ptr[a]:ptr[a + 1]], i[ptr[a]:ptr[a + 1], 0])}
    assert all((b, a, -im) in pairs for a, b, im in pairs)
    bp = BroadPhase(fr.elements, fr.contact_radius, fr.periods, fr.images, exclusions=(ptr, e, i))
    assert len(bp.pairs(fr.nodes, 0.01)["a"]) == 0
    with pytest.raises(InputError, match="margin"):
        arc_exclusions(fr, margin=-1.0)


def test_frame_stencil_on_a_periodic_frame():
    # two periodic yarns crossing: x-yarn at z = 0 and y-yarn at z = 0.205 (2-periodic)
    n, P = 8, 2.0
    s = np.linspace(0, P, n, endpoint=False)
    X = np.vstack([np.column_stack([s, np.full(n, 0.3), np.zeros(n)]),
                   np.column_stack([np.full(n, 0.7), s, np.full(n, 0.205)])])
    el = np.vstack([np.column_stack([np.arange(n), (np.arange(n) + 1) % n]),
                    np.column_stack([n + np.arange(n), n + (np.arange(n) + 1) % n])])
    img = np.zeros((2 * n, 2), int)
    img[n - 1] = (1, 0)
    img[2 * n - 1] = (0, 1)
    fr = homtex.Frame(X, el, radius=0.1, E=1000.0, nu=0.3, yarn=np.repeat([0, 1], n),
                      periods=[[P, 0, 0], [0, P, 0]], images=img)
    bp = BroadPhase(fr.elements, fr.contact_radius, fr.periods, fr.images, exclusions=arc_exclusions(fr))
    st = frame_stencil(fr, bp.pairs(fr.nodes, 0.02))
    enf = Enforcement("barrier", ghat=0.01, kappa=1.0)
    ev = pair_potential(fr.nodes, st, enf)
    assert ev.energy == pytest.approx(enf.energy(0.005)[0], rel=1e-10)   # one crossing per cell
    assert np.allclose(-ev.grad[n:, 2].sum(), -enf.energy(0.005)[1])
