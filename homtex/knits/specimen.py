"""A finite knitted specimen between grips (``homtex.tensile(..., specimen=(wales, courses))``).

The specimen is cut from the relaxed periodic cell, as a flat-knitted strip: ``wales`` needle
positions of ``courses`` courses of the relaxed geometry (the paper: 5 needles, 5 knitting cycles),
each course's yarn turning into the next at the selvedge by a half circle (one continuous yarn, as
a flat bed knits it; the turns are stress-free as generated). The knitted elements keep their rest
state (straight yarn); the free edges are out of equilibrium at first, so the specimen is first
released with its grips held (the energy it releases is counted as released, the relaxation's
ledger), then pulled. Grips: every node of the first course held (the bottom grip) and of the last
course moved along the wales (the top grip), like the paper's hat-shaped holders knitted in. The
force is the grips' reaction along the pull; the gauge length the grips' initial distance; the
width the specimen's x extent (initial: the needle positions x the needle pitch of the relaxed
cell).

Not yet working (measured on the E-glass jersey, 3 needles x 4 courses, 5 % in one level): the
cut edges settle (0.049 N mm released) but the pull does not converge (200 Newton iterations, the
out-of-balance force stays at 0.043 N, the status "failed" after 98 s of CPU): a jersey's free
edges curl, the soft mechanism the issue's probe met; the periodic cell is the tested path.
"""

from __future__ import annotations

import logging
import time

import numpy as np

from ..contact.engine import EngineStepper
from ..contact.incremental import IncrementalSolver
from ..contact.ipc_system import serial_numba
from ..errors import InputError, SolverError
from ..model.frame import Frame
from ..model.rest import RestState, start_rest
from .record import _attrs, _positions, _Recorder, finish, march, settings, stepping
from .relax import is_filament_bundle, knit_contact

log = logging.getLogger(__name__)

__all__ = ["build_specimen", "specimen_test"]


def _course_chain(frame, x, P, e_course):
    """Elements of one course in chain order and the unwrapped node positions along it."""
    el = frame.elements
    order = [int(e_course[0])]
    nxt = {int(el[e, 0]): int(e) for e in e_course}
    while len(order) < len(e_course):
        order.append(nxt[int(el[order[-1], 1])])
    order = np.array(order)
    vec = x[el[order, 1]] + frame.images[order] @ P - x[el[order, 0]]
    pts = x[el[order[0], 0]] + np.vstack([np.zeros(3), np.cumsum(vec, axis=0)])
    return order, pts


def build_specimen(relaxed, info, wales: int, courses: int, element_length: float):
    """(Frame, RestState, bottom grip nodes, top grip nodes, initial width mm) of a specimen
    (see the module docstring)."""
    pat = info["pattern"]
    frame = relaxed.cell.frame
    x = relaxed.state.ut + frame.nodes
    P = relaxed.frame.periods
    N = pat.n_needles * info["repeat"][0]
    C = pat.n_courses * info["repeat"][1]
    if is_filament_bundle(info):
        raise InputError("a finite specimen of separate filaments is not built; use the equivalent yarn "
                         "(yarn_model.model = 'equivalent') for specimens")
    nodes, els, src, ends = [], [], [], []
    for j in range(courses):
        c = j % C
        e_c = np.flatnonzero(info["course"] == c)
        order, pts = _course_chain(frame, x, P, e_c)
        n = len(order)
        reps = int(np.ceil(wales / N)) + 1
        full = np.vstack([pts[:-1] + q * P[0] for q in range(reps)] + [pts[-1:] + (reps - 1) * P[0]])
        srcs = np.tile(order, reps)
        cut = int(round(wales * n / N))
        seg = full[:cut + 1] + (j // C) * P[1]
        base = sum(len(a) for a in nodes)
        nodes.append(seg)
        els.append(base + np.c_[np.arange(cut), np.arange(1, cut + 1)])
        src.append(srcs[:cut])
        ends.append((base, base + cut))
    # selvedge turns: course j's right end to j+1's right end (j even), left ends (j odd)
    knit_m = sum(len(e) for e in els)
    turn_nodes, turn_els = [], []
    base = sum(len(a) for a in nodes)
    for j in range(courses - 1):
        side = 1 if j % 2 == 0 else 0
        a, b = nodes[j][-1 if side else 0], nodes[j + 1][-1 if side else 0]
        ia, ib = ends[j][side], ends[j + 1][side]
        centre, r = 0.5 * (a + b), 0.5 * np.linalg.norm(b - a)
        k = max(4, int(np.ceil(np.pi * r / element_length)))
        ang = np.linspace(-np.pi / 2, np.pi / 2, k + 1)[1:-1]
        u = (b - a) / (2 * r)
        out = np.array([1.0 if side else -1.0, 0.0, 0.0])
        out = out - (out @ u) * u
        out /= np.linalg.norm(out)
        pts = centre + r * (np.sin(ang)[:, None] * u + np.cos(ang)[:, None] * out)
        idx = base + np.arange(len(pts))
        chain = np.r_[ia, idx, ib]
        turn_nodes.append(pts)
        turn_els.append(np.c_[chain[:-1], chain[1:]])
        base += len(pts)
    allnodes = np.vstack(nodes + turn_nodes)
    allels = np.vstack(els + turn_els)
    srcs = np.concatenate(src)
    m_turn = len(allels) - knit_m
    fields = frame.element_fields(np.r_[srcs, np.full(m_turn, srcs[0])])
    fields["yarn"] = np.zeros(len(allels), dtype=np.int64)
    fields["ref"][knit_m:] = (0.0, 0.0, 1.0)            # the turns lie in the fabric plane
    spec = Frame(allnodes, allels, **fields)
    rest_turn = start_rest(spec).select(np.arange(knit_m, len(allels)))
    rest_knit = relaxed.rest.select(srcs)
    rest = RestState(length=np.r_[rest_knit.length, rest_turn.length],
                     frames=np.concatenate([rest_knit.frames, rest_turn.frames])).check(spec)
    bottom = np.arange(ends[0][0], ends[0][1] + 1)
    top = np.arange(ends[-1][0], ends[-1][1] + 1)
    width0 = wales * float(np.linalg.norm(P[0])) / N
    return spec, rest, bottom, top, width0


def specimen_test(relaxed, info, wales, courses, strain, v, steps, mu, progress, keep_positions, tol):
    """The finite-specimen tensile test (see the module docstring) as a tensile Dataset."""
    if v != 1:
        raise InputError("a finite specimen is pulled along the wales (direction='wale'), as the paper's")
    if wales < 1 or courses < 3:
        raise InputError(f"specimen = (wales, courses) needs wales >= 1 and courses >= 3 (two grips and a gauge), "
                         f"got ({wales}, {courses})")
    t0 = time.process_time()
    h = float(np.median(relaxed.cell.frame.length))
    spec, rest, bottom, top, width0 = build_specimen(relaxed, info, wales, courses, h)
    L0 = float(spec.nodes[top, 1].mean() - spec.nodes[bottom, 1].mean())
    contact = knit_contact(info, mu)
    fixed = {int(i): "all" for i in bottom}
    fixed.update({int(i): {0: 0.0, 1: strain * L0, 2: 0.0, 3: 0.0, 4: 0.0, 5: 0.0} for i in top})
    # 1. the cut edges let go with the grips held (energy released, the relaxation's ledger)
    rel = IncrementalSolver(spec, fixed, None, [], knit_contact(info, None), rest=rest,
                            settings=settings(info, tol, stabilization="released"))
    with serial_numba(rel.small):
        try:
            rel.solve(motion=0.0)
        except SolverError as err:
            raise SolverError(f"tensile specimen {wales} x {courses}: the cut specimen did not settle "
                              f"({err})") from None
    # 2. pulled by the top grip
    sol = IncrementalSolver(spec, fixed, None, [], contact, rest=rest, settings=settings(info, tol),
                            initial=rel.export_state())
    sol.delta = sol.s.delta0
    sol._start_ledger()
    stepper = EngineStepper(sol, lambda lam: sol.solve(motion=lam),
                            **stepping(info, sol.scene.has_friction))
    rec = _Recorder(sol, {**info, "course": np.zeros(spec.n_elements, int), "filament": np.zeros(spec.n_elements, int)},
                    info["yarn_model"].get("failure_stress"))
    mid = np.flatnonzero(np.abs(spec.nodes[:, 1] - 0.5 * (spec.nodes[top, 1].mean() + spec.nodes[bottom, 1].mean()))
                         < 0.25 * L0)
    pos, ee = [sol.positions.copy()], [sol.cor.energy.copy()]

    def add(s, it):
        x = sol.positions
        rec.add(s, float(sol._react[top, 1].sum()), float(np.ptp(x[mid, 0])), float(np.mean(x[top, 1]) -
                np.mean(spec.nodes[top, 1])), width0, it)

    add(0.0, 0)

    def level(s, iters):
        add(s, iters)
        if keep_positions:
            pos.append(sol.positions.copy())
            ee.append(sol.cor.energy.copy())

    status, detail = march(stepper, steps, strain, level, what="tensile specimen", progress=progress)
    attrs = _attrs(relaxed, info, f"finite specimen, {wales} needles x {courses} courses between grips", v, mu, L0,
                   width0, steps, sol, t0)
    attrs["released_at_cut_Nmm"] = float(rel.ledger["stabilization"])
    ds = rec.dataset(attrs)
    if keep_positions:
        _positions(ds, pos, ee)
    ds = finish(ds, rec, status, detail, sol, rec.info)
    ds.attrs["specimen_frame_nodes"] = int(spec.n_nodes)
    return ds
