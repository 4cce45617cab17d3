"""Narrow and broad phase of the contact search (closest points, grid, periodic images, exclusions)."""

import itertools

import numpy as np
import pytest

from homtex import Frame
from homtex.contact.broad import BroadPhase, exclusion_lists, find_pairs, find_pairs_kdtree
from homtex.contact.narrow import closest_points_reference, segment_pairs


def closest(a, u, b, v):
    p0 = np.array([a, b], float)
    d = np.array([u, v], float)
    s, t, dist, n = segment_pairs(p0, d, [0], [1])
    return s[0], t[0], dist[0], n[0]


def test_closest_points_random_against_sampling():
    rng = np.random.default_rng(1)
    for _ in range(60):
        a, u, b, v = rng.normal(size=(4, 3))
        par = rng.random() < 0.3
        if par:  # nearly parallel (angle ~1e-7): treated as parallel, middle of the overlap
            v = u * rng.uniform(-2, 2) + 1e-7 * rng.normal(size=3)
        s, t, dist, n = closest(a, u, b, v)
        # exactness: the returned points are at the returned distance, along the normal
        d = (a + s * u) - (b + t * v)
        assert np.isclose(np.linalg.norm(d), dist, rtol=1e-12, atol=1e-14)
        assert np.allclose(d, dist * n, atol=1e-12)
        # optimality against a dense sample of both segments
        _, _, dref = closest_points_reference(a, u, b, v, samples=401)
        h = (np.linalg.norm(u) + np.linalg.norm(v)) / 400
        # parallel branch (sin^2 angle < 1e-10): distance varies by <= angle x length over the overlap
        slack = 1e-5 * (np.linalg.norm(u) + np.linalg.norm(v)) if par else 1e-12
        assert dist <= dref + slack
        assert dist >= dref - h


def test_closest_points_crossing_parallel_and_collinear():
    # perpendicular crossing, one above the other: midpoints, normal +z
    s, t, dist, n = closest([-1, 0, 1], [2, 0, 0], [0, -1, 0], [0, 2, 0])
    assert (s, t) == pytest.approx((0.5, 0.5)) and dist == pytest.approx(1.0)
    assert n == pytest.approx([0, 0, 1])
    # parallel, overlapping on [0.5, 1] of segment 1: the middle of the overlap
    s, t, dist, n = closest([0, 0, 0], [2, 0, 0], [1, 0.3, 0], [2, 0, 0])
    assert s == pytest.approx(0.75) and t == pytest.approx(0.25) and dist == pytest.approx(0.3)
    assert n == pytest.approx([0, -1, 0])
    # antiparallel overlap gives the same points
    s2, t2, dist2, _ = closest([0, 0, 0], [2, 0, 0], [3, 0.3, 0], [-2, 0, 0])
    assert s2 == pytest.approx(0.75) and t2 == pytest.approx(0.75) and dist2 == pytest.approx(0.3)
    # parallel, disjoint: nearest ends
    s, t, dist, _ = closest([0, 0, 0], [1, 0, 0], [3, 1, 0], [1, 0, 0])
    assert (s, t) == pytest.approx((1.0, 0.0)) and dist == pytest.approx(np.hypot(2, 1))
    # collinear touching end to end: distance 0, normal a unit perpendicular
    s, t, dist, n = closest([0, 0, 0], [1, 0, 0], [1, 0, 0], [1, 0, 0])
    assert dist == pytest.approx(0.0, abs=1e-14) and abs(n @ [1, 0, 0]) < 1e-12
    assert np.linalg.norm(n) == pytest.approx(1.0)
    # clamped: segment 2 beyond the end of segment 1
    s, t, dist, _ = closest([0, 0, 0], [1, 0, 0], [2, -1, 0], [0, 2, 0])
    assert (s, t) == pytest.approx((1.0, 0.5)) and dist == pytest.approx(1.0)


def _brute(p0, d, r, margin, periods):
    m = len(p0)
    k = len(periods)
    out = set()
    imgs = list(itertools.product((-2, -1, 0, 1, 2), repeat=k)) if k else [()]
    for tau in imgs:
        tau = np.array(tau, dtype=np.int64)
        shift = tau @ periods if k else np.zeros(3)
        a, b = np.meshgrid(np.arange(m), np.arange(m), indexing="ij")
        a, b = a.ravel(), b.ravel()
        s, t, dist, _ = segment_pairs(p0, d, a, b, np.broadcast_to(shift, (len(a), 3)))
        ok = dist < r[a] + r[b] + margin
        for ai, bi in zip(a[ok], b[ok]):
            if ai < bi or (ai == bi and k and tau[np.flatnonzero(tau)[0]] > 0 if tau.any() else False):
                out.add((int(ai), int(bi), tuple(int(q) for q in tau)))
    return out


@pytest.mark.parametrize("k", [0, 2, 3])
def test_grid_broad_phase_matches_brute_force(k):
    rng = np.random.default_rng(k)
    m = 250
    box = np.array([6.0, 5.0, 4.0])
    p0 = rng.uniform(0, 1, size=(m, 3)) * box
    d = rng.normal(size=(m, 3))
    d *= rng.uniform(0.2, 1.0, size=(m, 1)) / np.linalg.norm(d, axis=1)[:, None]
    r = rng.uniform(0.05, 0.15, size=m)
    periods = np.diag(box)[:k]
    if k == 2:
        periods = np.array([[6.0, 0, 0], [1.5, 5.0, 0]])  # oblique cell
    got = find_pairs(p0, d, r, 0.1, periods)
    found = {(int(a), int(b), tuple(int(q) for q in i)) for a, b, i in zip(got["a"], got["b"], got["image"])}
    assert len(found) == len(got["a"])  # no duplicates
    assert found == _brute(p0, d, r, 0.1, periods)
    # parameters agree with the narrow phase
    shift = got["image"] @ periods if k else np.zeros((len(got["a"]), 3))
    s, t, dist, _ = segment_pairs(p0, d, got["a"], got["b"], shift)
    assert np.allclose(dist, got["dist"]) and np.allclose(s, got["s"]) and np.allclose(t, got["t"])


def test_grid_matches_kdtree_periodic_box():
    rng = np.random.default_rng(5)
    m = 3000
    box = np.array([10.0, 10.0, 10.0])
    p0 = rng.uniform(0, 10, size=(m, 3))
    d = rng.normal(size=(m, 3))
    d *= 0.4 / np.linalg.norm(d, axis=1)[:, None]
    r = np.full(m, 0.05)
    g = find_pairs(p0, d, r, 0.02, np.diag(box))
    q = find_pairs_kdtree(p0, d, r, 0.02, box=box)
    def key(res):
        return {(int(a), int(b), tuple(int(x) for x in i)) for a, b, i in zip(res["a"], res["b"], res["image"])}
    assert len(g["a"]) > 50
    assert key(g) == key(q)


def _polyline_frame(points, r=0.1, yarn=0, closed=False):
    n = len(points)
    el = [(i, i + 1) for i in range(n - 1)] + ([(n - 1, 0)] if closed else [])
    return Frame(points, el, radius=r, E=1000.0, nu=0.3, yarn=np.full(len(el), yarn))


def test_exclusions_neighbours_along_yarn_but_not_far_parts():
    # a U-shaped yarn made of short segments: the two legs touch, neighbours never count
    L = 0.05
    leg = np.arange(0, 2, L)
    x1 = np.column_stack([leg, 0 * leg, 0 * leg])
    th = np.linspace(-np.pi / 2, np.pi / 2, 30)[1:-1]
    arc = np.column_stack([2 + 0.1 * np.cos(th), 0.1 + 0.1 * np.sin(th), 0 * th])
    x2 = np.column_stack([leg[::-1], 0 * leg + 0.2, 0 * leg])
    fr = _polyline_frame(np.vstack([x1, arc, x2]), r=0.1)
    hops = int(np.ceil(0.3 / fr.length.min())) + 1
    ex = exclusion_lists(fr, hops)
    # each element excludes its neighbours within `hops` along the chain
    m = fr.n_elements
    for e in (0, m // 2, m - 1):
        lst = set(ex[1][ex[0][e]:ex[0][e + 1]].tolist())
        want = {f for f in range(max(0, e - hops), min(m, e + hops + 1)) if f != e}
        assert lst == want
    bp = BroadPhase(fr.elements, fr.contact_radius, exclusions=ex)
    pr = bp.pairs(fr.nodes, 0.01)
    sep = np.abs(pr["a"] - pr["b"])
    assert sep.min() > hops
    # the legs (distance 0.2 = r_a + r_b) are found along their length
    assert len(pr["a"]) >= len(leg) - 2


def test_periodic_exclusion_across_the_cell_boundary():
    # a straight periodic yarn of 4 elements: the element across the boundary is a neighbour
    nodes = np.column_stack([np.arange(4) * 0.25, np.zeros(4), np.zeros(4)])
    el = np.array([(0, 1), (1, 2), (2, 3), (3, 0)])
    img = np.array([[0], [0], [0], [1]])
    fr = Frame(nodes, el, radius=0.1, E=1.0, nu=0.3, periods=[[1.0, 0, 0]], images=img)
    ex = exclusion_lists(fr, 1)
    lst0 = {(int(f), tuple(i)) for f, i in zip(ex[1][ex[0][0]:ex[0][1]], ex[2][ex[0][0]:ex[0][1]])}
    assert lst0 == {(1, (0,)), (3, (-1,))}
    bp = BroadPhase(fr.elements, fr.contact_radius, fr.periods, fr.images, exclusion_lists(fr, 2))
    assert len(bp.pairs(fr.nodes, 0.05)["a"]) == 0
