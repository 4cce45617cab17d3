"""Bad-input campaign over the public API: how many bad inputs are refused by name, how many raise
anything else (the target is zero), and how many valid ones are accepted.

Three families, each counted:

- **Frame**: random arguments (hypothesis-style, seeded) replacing one constructor argument of a
  valid frame with a value drawn from bad kinds (NaN, infinities, huge, negative, zero, fractions for
  indices, strings, booleans, None, complex numbers, ragged and wrongly shaped arrays); an accepted
  frame must have finite geometry.
- **Cell files**: every leaf of every shipped cell file replaced by every bad kind of value
  (also integers beyond 64 bits and beyond double precision), deleted, or an unknown key added next
  to it, and every table replaced by a string, a number, an array or an empty table
  (`homtex.Cell` + build); an accepted cell must have a finite frame; every case must finish within
  a few seconds (sizes are bounded before allocation).
- **API**: every argument of `solve_static`, `homogenize`, `periodize`, `compress`, `seam_profile`,
  `macro_curve`, `load_cell`, `Contact`, `Plate`, `set_options` with the same bad kinds
  (`tests/test_api_inputs.py` runs this family as a test).

Usage::

    python studies/verification/input_campaign.py [--out DIR] [--quick] [--frames N]

Writes ``DIR/input_campaign.nc`` (outcome counts per family) and ``DIR/input_campaign.png``.
``--quick``: 300 random frames, three cell files and the tables of the spacer cell.
"""
import copy
import math
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import xarray as xr

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _common import ROOT, parser, pyplot, save_figure, save_netcdf, setup  # noqa: E402

OUTCOMES = ("refused by name", "refused, other culprit named", "accepted (valid)", "other exception")
KINDS = [math.nan, math.inf, -math.inf, -1, 0, 1e300, -1e300, 2.5, "x", True, None, 1 + 1j, [1, 2], {"a": 1}]
#: what a TOML file can hold beyond KINDS: integers beyond int64 (TOML itself stops at int64, but a
#: Cell made from a dict, or ``Cell.replace``, gets any Python int) and beyond float
CELL_KINDS = [*KINDS, 2 ** 70, -2 ** 70, 10 ** 400, [2 ** 70, 1]]
#: what replaces a whole table (a table where a value was expected is among CELL_KINDS)
TABLE_KINDS = ["x", 1, 2.5, True, [1, 2], [], {}]


def frame_family(n, seed=0):
    import homtex

    rng = np.random.default_rng(seed)
    nodes = np.array([[0.0, 0, 0], [1, 0, 0], [2, 0.5, 0], [2, 1, 0.3]])
    elements = np.array([[0, 1], [1, 2], [2, 3]])
    args = ["nodes", "elements", "radius", "E", "nu", "yarn", "semi_axes", "ref", "contact_radius", "prestrain",
            "bending_factor", "torsion_factor", "strain_limit", "periods", "images"]
    names = {"nodes": "node", "elements": "element", "semi_axes": "semi", "ref": "ref"}
    out = dict.fromkeys(OUTCOMES, 0)
    examples = []
    for _ in range(n):
        arg = args[rng.integers(len(args))]
        kind = KINDS[rng.integers(len(KINDS))]
        shape = {"nodes": (4, 3), "elements": (3, 2), "semi_axes": (3, 2), "ref": (3, 3), "periods": (1, 3),
                 "images": (3, 1)}.get(arg, (3,))
        if rng.random() < 0.5 and not isinstance(kind, (str, dict, list)) and kind is not None:
            v = np.full(shape, kind, dtype=object if isinstance(kind, (bool, complex)) else float)
            if arg == "nodes":
                v = nodes.astype(v.dtype) + 0 * v
                v[rng.integers(4), rng.integers(3)] = kind
        else:
            v = kind
        kw = dict(radius=0.1, E=1000.0, nu=0.3)
        if arg in ("nodes", "elements"):
            call = (v if arg == "nodes" else nodes, v if arg == "elements" else elements)
        else:
            call = (nodes, elements)
            kw[arg] = v
            if arg == "semi_axes":
                kw.pop("radius")
            if arg == "images":
                kw["periods"] = np.array([[3.0, 0, 0]])
            if arg == "periods":
                kw["images"] = np.array([[0], [0], [1]])
        try:
            f = homtex.Frame(*call, **kw)
            ok = all(np.all(np.isfinite(a)) for a in (f.nodes, f.length, f.R, f.A, f.Iy, f.J))
            out["accepted (valid)" if ok else "other exception"] += 1
            if not ok:
                examples.append(f"Frame {arg}={v!r}: accepted with non-finite geometry")
        except homtex.InputError as err:
            out["refused by name" if names.get(arg, arg).lower() in str(err).lower() else
                "refused, other culprit named"] += 1
        except Exception as err:  # noqa: BLE001 - counted
            out["other exception"] += 1
            examples.append(f"Frame {arg}={v!r}: {type(err).__name__}: {err}")
    return out, examples


def _leaves(d, prefix=()):
    for k, v in d.items():
        if isinstance(v, dict):
            yield from _leaves(v, prefix + (k,))
        else:
            yield prefix + (k,)


def _tables(d, prefix=()):
    for k, v in d.items():
        if isinstance(v, dict):
            yield prefix + (k,)
            yield from _tables(v, prefix + (k,))


def cell_family(paths, tables_only=()):
    """Every leaf of each cell file replaced by every value of CELL_KINDS, deleted, or joined by an
    unknown key, and every table replaced by every value of TABLE_KINDS (``tables_only``: files
    whose tables only are mutated)."""
    import homtex
    from homtex.cells import Cell

    try:
        import tomllib
    except ModuleNotFoundError:  # pragma: no cover
        import tomli as tomllib
    out = dict.fromkeys(OUTCOMES, 0)
    examples, slowest = [], 0.0
    with homtex.set_options(max_elements=30_000):
        for path in paths:
            data = tomllib.loads(path.read_text())
            cases = [] if path in tables_only else [(leaf, v) for leaf in _leaves(data)
                                                    for v in [*CELL_KINDS, "__delete__", "__unknown__"]]
            cases += [(table, v) for table in _tables(data) for v in TABLE_KINDS]
            for leaf, value in cases:
                d = copy.deepcopy(data)
                node = d
                for k in leaf[:-1]:
                    node = node[k]
                if value == "__delete__":
                    del node[leaf[-1]]
                elif value == "__unknown__":
                    node["no_such_key"] = 1.0
                else:
                    node[leaf[-1]] = value
                t0 = time.perf_counter()
                try:
                    Cell(d, path).build()
                    out["accepted (valid)"] += 1
                except homtex.InputError as err:
                    msg = str(err)
                    out["refused by name" if any(p in msg for p in leaf) or "no_such_key" in msg else
                        "refused, other culprit named"] += 1
                except Exception as err:  # noqa: BLE001 - counted
                    out["other exception"] += 1
                    examples.append(f"{path.name} {'.'.join(leaf)}={value!r}: {type(err).__name__}: {err}")
                slowest = max(slowest, time.perf_counter() - t0)
    return out, examples, slowest


def api_family():
    import homtex

    sys.path.insert(0, str(ROOT / "tests"))
    from test_api_inputs import BAD, _cases

    from homtex.config import OPTIONS
    before = dict(OPTIONS)
    out = dict.fromkeys(OUTCOMES, 0)
    examples = []
    for name, (fn, args) in _cases().items():
        for arg in args:
            for v in BAD:
                try:
                    fn(**{arg: v})
                    out["accepted (valid)"] += 1
                except (homtex.InputError, homtex.SolverError) as err:
                    named = isinstance(err, homtex.InputError) and arg.split("_")[0].lower() in str(err).lower()
                    out["refused by name" if named else "refused, other culprit named"] += 1
                except Exception as err:  # noqa: BLE001 - counted
                    out["other exception"] += 1
                    examples.append(f"{name}({arg}={v!r}): {type(err).__name__}: {err}")
                finally:
                    OPTIONS.update(before)
    return out, examples


def main(argv=None) -> None:
    p = parser(__file__, __doc__)
    p.add_argument("--frames", type=int, default=None, help="random Frame inputs (default 3000, --quick 300)")
    a = p.parse_args(argv)
    out = setup(a)
    warnings.simplefilter("ignore")
    n = a.frames or (300 if a.quick else 3000)
    cells = sorted((ROOT / "cells").glob("*.toml"))
    tables_only = ()
    if a.quick:   # three lattices in full, the spacer cell's tables (its nested tables: seam, bars, shape)
        tables_only = tuple(c for c in cells if c.stem == "spacer_20mm")
        cells = [c for c in cells if c.stem in ("square", "octet", "honeycomb")] + list(tables_only)
    t0 = time.perf_counter()
    fam = {}
    fam["Frame"], ex_f = frame_family(n)
    fam["cell files"], ex_c, slowest = cell_family(cells, tables_only)
    fam["public API"], ex_a = api_family()
    seconds = time.perf_counter() - t0
    counts = np.array([[fam[f][o] for o in OUTCOMES] for f in fam])
    ds = xr.Dataset(
        {"count": (("family", "outcome"), counts, {"units": "1", "long_name": "inputs tried with this outcome"}),
         "other_exceptions": ("example", np.array((ex_f + ex_c + ex_a) or [""], dtype=object),
                              {"units": "1", "long_name": "inputs that raised something other than InputError"})},
        coords={"family": ("family", list(fam), {"units": "1", "long_name": "input family"}),
                "outcome": ("outcome", list(OUTCOMES), {"units": "1", "long_name": "what the input gave"}),
                "example": ("example", np.arange(max(1, len(ex_f + ex_c + ex_a))),
                            {"units": "1", "long_name": "index"})},
        attrs={"frames": n, "cell_files": ", ".join(c.name for c in cells), "seconds": seconds,
               "slowest_cell_case_s": slowest})
    save_netcdf(ds, out / "input_campaign.nc")
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(8, 3.8))
    left = np.zeros(len(fam))
    for j, o in enumerate(OUTCOMES):
        ax.barh(list(fam), counts[:, j], left=left, label=o)
        left += counts[:, j]
    ax.set(xlabel="inputs tried, 1", title="bad-input campaign: outcome per input family (target: no other exception)")
    ax.legend(fontsize=8, loc="lower right")
    fig.tight_layout()
    save_figure(fig, out / "input_campaign.png")
    for f in fam:
        print(f"{f:12s} " + ", ".join(f"{o}: {fam[f][o]}" for o in OUTCOMES))
    print(f"{seconds:.1f} s; slowest cell case {slowest:.2f} s")
    for e in (ex_f + ex_c + ex_a)[:20]:
        print("  ", e)


if __name__ == "__main__":
    main()
