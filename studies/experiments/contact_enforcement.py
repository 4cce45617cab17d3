"""Barrier or smoothed penalty? A measured choice of the contact enforcement (issue 18).

Toy problems with translations only (spring chains: axial springs between neighbours, second-
neighbour springs for bending, weak anchor springs; r = 0.1 mm; loads of ~1 N per node), each
solved from its unloaded state with the whole load in one step, by Newton on
Pi(x) = springs + contact potential - f . u with an Armijo backtracking line search whose first
trial step is capped by the CCD bound (:mod:`homtex.contact.ccd`, gaps kept >= 10 % of their
value) -- the structure of the future nonlinear driver:

* ``plate``: a free chain pressed onto a plate by random node loads (exact: every node at
  gap 0, reaction = load - anchor force);
* ``crossing``: a chain pinned at its ends pressed by a point load onto a fixed crossing yarn
  (exact: gap 0 at the middle node, reaction from the spring system with that node held);
* ``parallel``, ``blend``: a chain (moving along z only: on top of a cylinder it would roll
  off) pressed onto a fixed straight yarn under it at 0 deg (the nodal line-contact form) and
  at 1.5 deg (inside the parallel blend); exact: every node on the yarn's surface;
* ``friction``: a chain of 5 nodes pressed on a plate (mu = 0.3) and dragged by a spring in
  12 steps (exact: it slides at mu N; error = the plateau force's).

For each enforcement, activation gap ghat in {0.3, 0.1, 0.03, 0.01} r and stiffness kappa =
kfac * F / ghat (F the load per node, kfac in {0.1, 1, 10, 100}) it records Newton iterations,
line-search cuts, steps limited by the CCD, wall time, the gap error against the exact answer
(max |gap| over the contacts that close, mm) and the contact-force error.

The first trial step is either the CCD bound or, for comparison, the displacement cap of 4C
(no node moves more than r per step).

Result of the full grid (5 problems x 16 (ghat, kappa) per enforcement; ~40 s here):

* barrier + CCD converged in 80 of 80 runs, median Newton iterations 9 (plate), 7 (crossing),
  7 (parallel), 17 (blend), 4.2 per step (friction); every state stays intersection-free. Its
  gap error is the equilibrium gap, about kfac * ghat (6e-5 r to 0.29 r over the grid), and
  it reaches 3e-3 r on every problem.
* penalty + CCD (centre lines only: a penalty must be free to penetrate) converged in 72 of 80:
  too soft a kappa (kfac 0.1) asks for a penetration beyond the yarn and the centre-line check
  traps it. Where it converges it needs as few or fewer iterations (median 6, 2, 7, 23, 4.2),
  but its error |ghat / 2 - F / kappa| depends on the unknown contact force: it reached 3e-3 r
  only on the two line contacts, never on the plate or the crossing.
* the displacement cap instead of the CCD: the barrier still converges (its line search
  rejects the infinite energies) but with 1.1-4x the iterations (median 36 plate, 51 blend)
  and 4-50x the line-search cuts; the penalty converges more often but some runs end with a
  node's centre through the plate (gap error 1.5 r).

Choice: the IPC barrier with the CCD-capped line search: robust on every problem, never
penetrating, and its accuracy is set by parameters alone. ghat about 1-3 % of the smallest
contact radius (0.001-0.003 mm for the 0.1 mm pile), kappa about 0.1-1 x (expected contact
force per contact) / ghat, raised if gaps fall far below ghat (IPC's adaptive kappa). A barrier
cannot start from an overlap: initial geometries must have positive gaps (or be relaxed
first, e.g. with the C2 penalty, which the kernels keep for that).

Usage::

    python studies/experiments/contact_enforcement.py [OUT] [--quick] [--no-docs]

Writes ``OUT/contact_enforcement.nc`` and ``OUT/contact_enforcement.png`` (default
OUT = results/contact_enforcement) and copies the chart to ``docs/studies/``; prints a summary
(``-v`` logs every run).
"""

from __future__ import annotations

import logging
import shutil
import sys
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from homtex.contact.ccd import displacement_cap, pair_step_bound, plate_step_bound
from homtex.contact.friction import friction_potential, plate_friction_lag
from homtex.contact.plates import plate_gaps, plate_potential
from homtex.contact.potential import Enforcement, assemble_blocks, pair_gaps, pair_potential
from homtex.contact.stencil import pair_stencil

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _common import parser, setup  # noqa: E402

R = 0.1                    # yarn radius, mm
F = 1.0                    # load per node, N
KA, KB, KS = 200.0, 20.0, 2.0     # axial, bending (second neighbour), anchor springs, N/mm
GHATS = (0.3, 0.1, 0.03, 0.01)    # x R
KFACS = (0.1, 1.0, 10.0, 100.0)
KINDS = ("barrier", "penalty")
PROBLEMS = ("plate", "crossing", "parallel", "blend", "friction")
STEPS = ("ccd", "cap")            # first trial step: the CCD bound or the displacement cap (r)
MU, EPS_V = 0.3, 1e-4
log = logging.getLogger(__name__)


# ----------------------------------------------------------------------------------------
def chain_stiffness(n, pinned=(), anchor=True, only_z=False):
    """3n x 3n stiffness of a chain: neighbour, second-neighbour and (optional) anchor springs
    (linear, the same in x, y, z), and the mask of free DOFs."""
    rows, cols, vals = [], [], []
    for k, off in ((KA, 1), (KB, 2)):
        for i in range(n - off):
            j = i + off
            rows += [i, j, i, j]
            cols += [i, j, j, i]
            vals += [k, k, -k, -k]
    if anchor:
        rows += list(range(n))
        cols += list(range(n))
        vals += [KS] * n
    K1 = sp.csr_matrix((vals, (rows, cols)), shape=(n, n))
    free = np.ones((n, 3), dtype=bool)
    free[list(pinned)] = False
    if only_z:
        free[:, :2] = False
    return sp.kron(K1, sp.eye(3)).tocsr(), free.ravel()


def problem(name, seed=0):
    """Geometry, stiffness, loads and contact definition of a toy problem."""
    rng = np.random.default_rng(seed)
    n = 5 if name == "friction" else 21      # a short chain slides as a whole within the drag
    s = np.linspace(-2.0, 2.0, n)
    p = dict(name=name, n=n, plate=None, pair=None, gap0=0.1)
    if name in ("plate", "friction"):
        X = np.column_stack([s, np.zeros(n), np.full(n, R + 0.1)])
        K, free = chain_stiffness(n, anchor=name == "plate")     # a dragged chain has no anchors
        load = F * (rng.uniform(0.5, 1.5, n) if name == "plate" else np.ones(n))
        p.update(plate=dict(nodes=np.arange(n), radius=R, origin=[0, 0, 0], normal=[0, 0, 1]))
        p["exact_lam"] = load - KS * 0.1
    elif name == "crossing":
        X = np.column_stack([s, np.zeros(n), np.zeros(n)])
        K, free = chain_stiffness(n, pinned=(0, n - 1))
        load = np.zeros(n)
        load[n // 2] = 20 * F
        Xo = np.array([[0.0, -1.0, -2 * R - 0.05], [0.0, 1.0, -2 * R - 0.05]])
        p["pair"] = (Xo, np.arange(n - 1), np.zeros(n - 1, dtype=np.int64))
        p["gap0"] = 0.05
        # exact: the middle node held at the contact height
        f = np.zeros(3 * n)
        f[2::3] = -load
        held = free.copy()
        held[3 * (n // 2) + 2] = False
        u = np.zeros(3 * n)
        u[3 * (n // 2) + 2] = -0.05
        Kff = K[held][:, held]
        u[held] = spla.spsolve(Kff.tocsc(), f[held] - K[held] @ u)
        p["exact_lam"] = float((K @ u - f)[3 * (n // 2) + 2])
    else:
        angle = 0.0 if name == "parallel" else 1.5
        th = np.radians(angle)
        X = np.column_stack([s * np.cos(th), s * np.sin(th), np.full(n, 2 * R + 0.1)])
        K, free = chain_stiffness(n, only_z=True)     # on top of a cylinder: held laterally
        load = F * np.ones(n)
        m = 25
        so = np.linspace(-2.6, 2.6, m)
        Xo = np.column_stack([so, np.zeros(m), np.zeros(m)])
        # every segment of the chain against every segment of the fixed yarn
        p["pair"] = (Xo, np.repeat(np.arange(n - 1), m - 1), np.tile(np.arange(m - 1), n - 1))
        # exact: every node on the fixed yarn's surface, z = sqrt(4 R^2 - y^2); its contact force
        # balances the load and the springs at that state
        u = np.zeros((n, 3))
        u[:, 2] = np.sqrt(4 * R ** 2 - X[:, 1] ** 2) - X[:, 2]
        p["exact_lam"] = load + (K @ u.ravel())[2::3]
    f = np.zeros((n, 3))
    f[:, 2] = -load
    p.update(X=X, K=K, free=free, f=f.ravel(), load=load)
    if p["pair"] is not None:
        Xo, ea, eb = p["pair"]
        no = len(Xo)
        el = np.vstack([np.column_stack([np.arange(n - 1), np.arange(1, n)]),
                        n + np.column_stack([np.arange(no - 1), np.arange(1, no)])])
        p["X_all"] = np.vstack([X, Xo])
        p["stencil"] = pair_stencil(el, np.full(len(el), R), ea, (n - 1) + eb)
    return p


# ----------------------------------------------------------------------------------------
class Toy:
    """Pi(x) for a problem: springs + contact (+ lagged friction) - f . u, on the free DOFs."""

    def __init__(self, p, enf, step="ccd"):
        self.p, self.enf, self.step = p, enf, step
        self.n = p["n"]
        self.lag = None

    def full(self, xc):
        return np.vstack([xc, self.p["X_all"][self.n:]]) if self.p["pair"] is not None else xc

    def __call__(self, xc, hess=True):
        p = self.p
        u = (xc - p["X"]).ravel()
        E = 0.5 * u @ (p["K"] @ u) - p["f"] @ u
        g = p["K"] @ u - p["f"]
        H = p["K"].copy()
        n = self.n
        if p["plate"] is not None:
            c = plate_potential(xc, enforcement=self.enf, hessian=hess, **p["plate"])
            E += c.energy
            g = g + c.grad.ravel()
            if hess:
                H = H + assemble_blocks(c.hess, c.hess_nodes, n)
        if p["pair"] is not None:
            c = pair_potential(self.full(xc), p["stencil"], self.enf, hessian=hess)
            E += c.energy
            g = g + c.grad[:n].ravel()
            if hess and c.n_active:
                H = H + assemble_blocks(c.hess, c.hess_nodes, len(p["X_all"]))[:3 * n, :3 * n]
        if self.lag is not None:
            fr = friction_potential(self.lag, xc, self.x_start, EPS_V, hessian=hess)
            E += fr.energy
            g = g + fr.grad.ravel()
            if hess:
                H = H + assemble_blocks(fr.hess, fr.hess_nodes, n)
        return E, g, H

    def step_bound(self, xc, dx):
        if self.step == "cap":
            return displacement_cap(dx, R)
        a = 1.0
        p = self.p
        surf = self.enf.kind == "barrier"      # a penalty may penetrate: only the centre lines count
        if p["plate"] is not None:
            a = min(a, plate_step_bound(xc, dx, eta=0.1, use_radii=surf, **p["plate"]))
        if p["pair"] is not None:
            dfull = np.vstack([dx, np.zeros((len(p["X_all"]) - self.n, 3))])
            a = min(a, pair_step_bound(self.full(xc), dfull, p["stencil"], eta=0.1, use_radii=surf))
        return a


def newton(toy, x, tol=1e-9, max_iter=300):
    """Newton with a CCD-capped Armijo line search. Returns (x, iterations, cuts, ccd_limited, ok)."""
    free = toy.p["free"]
    scale = np.abs(toy.p["f"]).max()
    cuts = limited = 0
    for it in range(max_iter):
        E, g, H = toy(x)
        if np.abs(g[free]).max() <= tol * scale:
            return x, it, cuts, limited, True
        dx = np.zeros(x.size)
        Hff = H[free][:, free].tocsc()
        dx[free] = spla.spsolve(Hff, -g[free])
        dx = dx.reshape(-1, 3)
        a = toy.step_bound(x, dx)
        limited += a < 1.0
        slope = g @ dx.ravel()
        if slope >= 0:                       # not a descent direction (should not happen: PSD blocks)
            return x, it, cuts, limited, False
        if -slope < 1e-13 * max(abs(E), 1.0):
            x = x + a * dx                   # the decrease is below round-off of Pi: take the step
            continue
        while True:
            Et = toy(x + a * dx, hess=False)[0]
            if Et <= E + 1e-4 * a * slope or a < 1e-14:
                break
            a *= 0.5
            cuts += 1
        if a < 1e-14:
            return x, it, cuts, limited, False
        x = x + a * dx
    return x, max_iter, cuts, limited, False


def start_state(p, enf):
    """Unloaded start; for ``friction`` the chain rests on the plate at its equilibrium gap."""
    x = p["X"].copy()
    if p["name"] == "friction":
        lo, hi = -1.0, enf.ghat
        for _ in range(200):
            g = 0.5 * (lo + hi)
            lo, hi = (g, hi) if -enf.energy(g)[1] > F - KS * 0.0 else (lo, g)
        x[:, 2] = R + g
    return x


def solve(name, kind, ghat, kappa, step="ccd"):
    p = problem(name)
    enf = Enforcement(kind, ghat=ghat, kappa=kappa)
    toy = Toy(p, enf, step)
    t0 = time.perf_counter()
    x = start_state(p, enf)
    if name != "friction":
        x, it, cuts, lim, ok = newton(toy, x)
        gap_err, force_err = errors(p, toy, x)
        return dict(ok=ok, it=it, cuts=cuts, lim=lim, sec=time.perf_counter() - t0, gap=gap_err, force=force_err)
    return drag(p, toy, x, t0)


def drag(p, toy, x, t0, steps=12, du=0.02):
    """The friction problem: a pull spring (KA) on node 0, anchor moved du per step."""
    n = p["n"]
    p["X"] = x.copy()                       # springs relaxed at the resting state
    p["f"] = np.zeros(3 * n)
    p["f"][2::3] = -F
    K0 = p["K"]
    it_all = cuts_all = lim_all = 0
    forces = []
    ok = True
    U = 0.0
    for _ in range(steps):
        U += du
        toy.x_start = x.copy()
        toy.lag = plate_friction_lag(x, enforcement=toy.enf, mu=MU, **p["plate"])
        pull = sp.csr_matrix(([KA], ([0], [0])), shape=(3 * n, 3 * n))
        p["K"] = K0 + pull
        p["f"][0] = KA * U                  # the spring to the anchor: K u - KA U on node 0's x
        x, it, cuts, lim, conv = newton(toy, x)
        ok &= conv
        it_all += it
        cuts_all += cuts
        lim_all += lim
        forces.append(KA * (U - (x[0, 0] - p["X"][0, 0])))
    gaps = plate_gaps(x, **p["plate"])
    N = -toy.enf.energy(gaps)[1].sum()
    force_err = abs(np.mean(forces[-4:]) - MU * N) / (MU * N)
    return dict(ok=ok, it=it_all / steps, cuts=cuts_all, lim=lim_all, sec=time.perf_counter() - t0,
                gap=float(np.abs(gaps).max()), force=force_err)


def errors(p, toy, x):
    """Max |gap| over the contacts that close in the exact answer, and the force error."""
    if p["plate"] is not None:
        gaps = plate_gaps(x, **p["plate"])
        lam = -toy.enf.energy(gaps)[1]
        return float(np.abs(gaps).max()), float(np.abs(lam - p["exact_lam"]).max() / np.abs(p["exact_lam"]).max())
    ev = pair_potential(toy.full(x), p["stencil"], toy.enf, hessian=False)
    n = p["n"]
    fz = -ev.grad[:n, 2]                    # contact force on the chain's nodes
    if p["name"] == "crossing":
        gap = pair_gaps(toy.full(x), p["stencil"]).min()
        return float(abs(gap)), float(abs(fz.sum() - p["exact_lam"]) / p["exact_lam"])
    # chain on a fixed yarn (the x axis): its nodes rest on the yarn's surface in the exact answer
    gaps = np.hypot(x[:, 1], x[:, 2]) - 2 * R
    return float(np.abs(gaps).max()), float(np.abs(fz - p["exact_lam"]).max() / np.abs(p["exact_lam"]).max())


# ----------------------------------------------------------------------------------------
def run(out: Path, quick=False, docs=True):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import xarray as xr

    out.mkdir(parents=True, exist_ok=True)
    ghats = GHATS[1:3] if quick else GHATS
    kfacs = KFACS[:3] if quick else KFACS
    problems = PROBLEMS[:2] + ("friction",) if quick else PROBLEMS
    shape = (len(problems), len(KINDS), len(STEPS), len(ghats), len(kfacs))
    keys = ("ok", "it", "cuts", "lim", "sec", "gap", "force")
    res = {k: np.full(shape, np.nan) for k in keys}
    for idx in np.ndindex(*shape):
        a, b, e, c, d = idx
        ghat = ghats[c] * R
        r = solve(problems[a], KINDS[b], ghat, kfacs[d] * F / ghat, STEPS[e])
        log.info("%s %s %s ghat %.1e kfac %g: %s", problems[a], KINDS[b], STEPS[e], ghat, kfacs[d], r)
        for k in keys:
            res[k][idx] = r[k]
    dims = ("problem", "enforcement", "step", "ghat", "kfac")
    meta = {"ok": ("1", "converged (residual < 1e-9 of the load)"),
            "it": ("1", "Newton iterations (per step: friction)"),
            "cuts": ("1", "line-search halvings"), "lim": ("1", "Newton steps limited by the CCD bound or the cap"),
            "sec": ("s", "wall time"), "gap": ("mm", "max |gap| error against the exact answer"),
            "force": ("1", "relative contact (friction: sliding) force error")}
    names = {"ok": "converged", "it": "newton_iterations", "cuts": "line_search_cuts", "lim": "limited_steps",
             "sec": "seconds", "gap": "gap_error", "force": "force_error"}
    ds = xr.Dataset({names[k]: (dims, res[k], {"units": meta[k][0], "long_name": meta[k][1]}) for k in keys},
                    coords={"problem": list(problems), "enforcement": list(KINDS),
                            "step": ("step", list(STEPS), {"long_name": "first trial step: CCD bound (eta 0.1) "
                                                                        "or displacement cap (r)"}),
                            "ghat": ("ghat", np.asarray(ghats) * R, {"units": "mm", "long_name": "activation gap"}),
                            "kfac": ("kfac", np.asarray(kfacs), {"units": "1",
                                                                  "long_name": "kappa * ghat / load per node"})},
                    attrs={"radius_mm": R, "load_per_node_N": F, "mu": MU, "eps_v_mm": EPS_V,
                           "springs_N_per_mm": f"axial {KA}, bending {KB}, anchor {KS}",
                           "description": __doc__.split("\n\n")[0]})
    ds.to_netcdf(out / "contact_enforcement.nc")

    fig, axes = plt.subplots(1, len(problems), figsize=(3.3 * len(problems), 3.6), sharey=True)
    for ax, name in zip(np.atleast_1d(axes), problems):
        for kind, mk, col in (("barrier", "o", "C0"), ("penalty", "s", "C3")):
            for step, fill in (("ccd", True), ("cap", False)):
                sel = ds.sel(problem=name, enforcement=kind, step=step)
                ok = sel.converged.values.astype(bool)
                it = sel.newton_iterations.values
                ax.scatter(sel.gap_error.values[ok] / R, it[ok], marker=mk, alpha=0.75,
                           facecolors=col if fill else "none", edgecolors=col, label=f"{kind}, {step}")
                if (~ok).any():
                    ax.scatter(np.full((~ok).sum(), 3.0), np.minimum(it[~ok], 300), marker="x", color=col)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_title(name)
        ax.set_xlabel("gap error / r  (x at 3: not converged)")
        ax.grid(alpha=0.3, which="both")
    np.atleast_1d(axes)[0].set_ylabel("Newton iterations (friction: per step)")
    np.atleast_1d(axes)[0].legend(fontsize=7)
    fig.suptitle("Contact enforcement: accuracy vs Newton iterations over ghat and kappa (x: not converged)",
                 fontsize=9)
    fig.tight_layout()
    fig.savefig(out / "contact_enforcement.png", dpi=110)
    plt.close(fig)
    if docs:
        dst = Path(__file__).resolve().parents[2] / "docs" / "studies"
        dst.mkdir(parents=True, exist_ok=True)
        shutil.copy(out / "contact_enforcement.png", dst / "contact_enforcement.png")
    return ds


def summary(ds):
    """Per problem, enforcement and step control: runs converged, iterations, gap errors."""
    lines = []
    for name in ds.problem.values:
        for kind in ds.enforcement.values:
            for step in ds.step.values:
                s = ds.sel(problem=name, enforcement=kind, step=step)
                ok = s.converged.values.astype(bool)
                it = s.newton_iterations.values[ok]
                ge = s.gap_error.values[ok] / R
                lines.append(f"{name:9s} {kind:8s} {step:4s} converged {ok.sum():2d}/{ok.size}  iterations median "
                             f"{np.median(it) if ok.any() else np.nan:6.1f} max {it.max() if ok.any() else np.nan:6.1f}"
                             f"  cuts {int(np.nansum(s.line_search_cuts.values[ok])):5d}  gap error / r "
                             f"{ge.min() if ok.any() else np.nan:.1e} .. {ge.max() if ok.any() else np.nan:.1e}")
    return "\n".join(lines)


def main(argv=None) -> None:
    p = parser(__file__, __doc__)
    p.add_argument("--no-docs", action="store_true", help="do not copy the chart to docs/studies")
    p.add_argument("-v", action="store_true", help="log every run")
    a = p.parse_args(argv)
    out = setup(a)
    logging.getLogger().setLevel(logging.INFO if a.v else logging.WARNING)
    print(summary(run(out, quick=a.quick, docs=not (a.no_docs or a.quick))))


if __name__ == "__main__":
    main()
