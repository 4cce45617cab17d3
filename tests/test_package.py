"""The house rules of the package, checked on its source: an acyclic import graph (function-level
imports included), modules and functions of bounded size, no print outside the command line,
the public API as promised."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import homtex

ROOT = Path(homtex.__file__).resolve().parent
MAX_MODULE_LINES = 600
MAX_FUNCTION_LINES = 150


def _modules() -> dict[str, Path]:
    out = {}
    for p in ROOT.rglob("*.py"):
        parts = list(p.relative_to(ROOT.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = p
    return out


def import_graph() -> dict[str, set]:
    """module -> homtex modules it imports anywhere in its source (functions included)."""
    mods = _modules()
    edges: dict[str, set] = {m: set() for m in mods}
    for m, p in mods.items():
        is_pkg = p.name == "__init__.py"
        for node in ast.walk(ast.parse(p.read_text())):
            if isinstance(node, ast.ImportFrom):
                if node.level:
                    base = m.split(".") if is_pkg else m.split(".")[:-1]
                    base = base[:len(base) - (node.level - 1)]
                    target = ".".join(base + ([node.module] if node.module else []))
                else:
                    target = node.module or ""
                cands = [target] + [f"{target}.{a.name}" for a in node.names]
            elif isinstance(node, ast.Import):
                cands = [a.name for a in node.names]
            else:
                continue
            edges[m].update(c for c in cands if c in mods and c != m)
    return edges


def find_cycle(edges: dict[str, set]) -> list:
    """One cycle of the graph as a list of modules, or [] if it is acyclic."""
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(v):
        state[v] = 1
        stack.append(v)
        for w in sorted(edges.get(v, ())):
            if state.get(w) == 1:
                return stack[stack.index(w):] + [w]
            if w not in state:
                cyc = visit(w)
                if cyc:
                    return cyc
        stack.pop()
        state[v] = 2
        return []

    for v in sorted(edges):
        if v not in state:
            cyc = visit(v)
            if cyc:
                return cyc
    return []


def test_the_import_graph_is_acyclic():
    assert find_cycle(import_graph()) == []


def test_the_cycle_finder_finds_a_cycle():
    # the check above must be able to fail
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b"}, "b": set()}) == []


def test_the_analysis_core_does_not_import_contact_or_seams():
    edges = import_graph()
    for m, targets in edges.items():
        if m.startswith(("homtex.analysis", "homtex.model", "homtex.fem", "homtex.linalg", "homtex.geometry")):
            bad = [t for t in targets if t.startswith(("homtex.contact", "homtex.seams", "homtex.app",
                                                       "homtex.study", "homtex.api"))]
            assert not bad, f"{m} imports {bad} (a lower room imports a higher one)"


def test_modules_and_functions_stay_small():
    long_modules, long_functions = [], []
    for m, p in _modules().items():
        text = p.read_text()
        if len(text.splitlines()) > MAX_MODULE_LINES:
            long_modules.append((m, len(text.splitlines())))
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                n = node.end_lineno - node.lineno + 1
                if n > MAX_FUNCTION_LINES:
                    long_functions.append((m, node.name, n))
    assert long_modules == [], f"modules over {MAX_MODULE_LINES} lines: {long_modules}"
    assert long_functions == [], f"functions over {MAX_FUNCTION_LINES} lines: {long_functions}"


def test_no_print_outside_the_command_line():
    offenders = []
    for m, p in _modules().items():
        if m.startswith("homtex.app"):
            continue
        for node in ast.walk(ast.parse(p.read_text())):
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "print":
                offenders.append(f"{m}:{node.lineno}")
    assert offenders == [], f"print() in library code (use logging): {offenders}"


@pytest.mark.parametrize("name", ["Frame", "solve_static", "homogenize", "periodize", "load_cell", "compress",
                                  "Contact", "Plate", "seam_profile", "seam_compression", "macro_curve",
                                  "run_study", "Lookup", "solve_nonlinear", "Corotational", "InputError",
                                  "SolverError", "set_options", "get_options", "Status"])
def test_public_names(name):
    assert name in homtex.__all__
    assert getattr(homtex, name) is not None


def test_options_are_validated_and_restored():
    from homtex.config import OPTIONS

    before = dict(OPTIONS)
    with homtex.set_options(static_solver="direct", tol=1e-8):
        assert homtex.get_options()["static_solver"] == "direct" and OPTIONS["tol"] == 1e-8
    assert OPTIONS == before
    for bad in ({"tol": 1.0}, {"tol": float("nan")}, {"static_solver": "magic"}, {"no_such_option": 1},
                {"threads": 0}, {"progress": "yes"}):
        with pytest.raises(homtex.InputError, match=next(iter(bad))):
            homtex.set_options(**bad)
    assert OPTIONS == before


def test_the_default_solver_comes_from_the_options():
    import numpy as np

    nodes = np.c_[np.linspace(0, 10, 3), np.zeros(3), np.zeros(3)]
    fr = homtex.Frame(nodes, [[0, 1], [1, 2]], radius=0.5, E=1000.0, nu=0.3)
    with homtex.set_options(static_solver="direct"):
        r = homtex.solve_static(fr, {0: "all"}, {2: (0, 0, -1.0, 0, 0, 0)})
    assert r.report.method.startswith("direct")
    r = homtex.solve_static(fr, {0: "all"}, {2: (0, 0, -1.0, 0, 0, 0)})
    assert r.report.method == "amg"


def test_small_problems_run_on_one_numba_thread_by_default(monkeypatch):
    """threads=None: all cores for large problems, one thread below SERIAL_BELOW_DOF (a linear
    spacer compression took 3.0 s on 2 threads next to a busy process, 1.7 s on one); an explicit
    threads setting is kept for every size."""
    import numba

    import homtex.contact.compress as cc
    from homtex.config import SERIAL_BELOW_DOF, threads_for

    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("one core: nothing to limit")
    all_threads = numba.get_num_threads()
    assert all_threads > 1
    with threads_for(SERIAL_BELOW_DOF - 1):
        assert numba.get_num_threads() == 1
    assert numba.get_num_threads() == all_threads
    with threads_for(SERIAL_BELOW_DOF):
        assert numba.get_num_threads() == all_threads
    with homtex.set_options(threads=2), threads_for(10):
        assert numba.get_num_threads() == 2
    seen = []
    real = cc.march

    def spy(*a, **k):
        seen.append(numba.get_num_threads())
        return real(*a, **k)

    monkeypatch.setattr(cc, "march", spy)
    homtex.compress(homtex.load_cell("spacer_20mm"), strain=0.02, steps=1, geometry="linear")
    assert seen == [1] and numba.get_num_threads() == all_threads
