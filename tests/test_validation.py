"""Every bad input to a Frame or a cell file raises InputError naming the argument (never another
exception, never a silent acceptance), and every accepted input gives finite geometry.

Property-based (hypothesis): a valid frame with one argument replaced by a value drawn from a
catalogue of bad kinds (non-finite, complex, strings, booleans, wrong shapes, huge, non-integral
indices, out of range) must be refused with the argument's name in the message; random numbers
for every argument must either be refused that way or give a frame whose lengths, axes and section
properties are finite.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import homtex

NODES = np.array([[0.0, 0, 0], [1, 0, 0], [2, 0.5, 0], [2, 1, 0.3]])
ELEMENTS = np.array([[0, 1], [1, 2], [2, 3]])
BASE = dict(radius=0.1, E=1000.0, nu=0.3)
M = 3

#: words that name each argument in its error message
NAMES = {"nodes": "node", "elements": "element", "radius": "radius", "E": "E", "nu": "nu", "yarn": "yarn",
         "semi_axes": "semi", "ref": "ref", "periods": "periods", "images": "images",
         "contact_radius": "contact_radius", "prestrain": "prestrain", "bending_factor": "bending_factor",
         "torsion_factor": "torsion_factor"}

NON_NUMBERS = [np.nan, np.inf, -np.inf, "1.0", b"x", 1 + 2j, True, None, object(), [1.0, "a"]]


def bad_values(arg):
    """Bad values for one argument (the argument is replaced in a valid 3-element frame)."""
    common = [np.nan, np.inf, -np.inf, "1", 1 + 1j, np.array([1 + 1j] * M), True, np.array([True] * M),
              [[1.0, 2.0], [3.0]], np.zeros((2, 2)), np.ones(M + 1), {"a": 1}]
    per = {
        "nodes": [NODES.astype(complex), NODES[:, :2], NODES.ravel(), np.where(NODES == 1, np.nan, NODES),
                  NODES * 1e200, "nodes", NODES.astype(str), np.array([[0, 0, 0]] * 4, dtype=object)],
        "elements": [ELEMENTS + 0.5, np.where(ELEMENTS == 1, np.nan, ELEMENTS), ELEMENTS.astype(complex),
                     ELEMENTS * 1e30, ELEMENTS.astype(str), ELEMENTS[:, :1], ELEMENTS + 10, -ELEMENTS - 1,
                     np.zeros((0, 2), int), [[0, 1], [1]]],
        "radius": [-0.1, 0.0, 1e300, np.array([0.1, -0.1, 0.1])],
        "E": [-1.0, 0.0, 1e300],
        "nu": [0.5, -1.0, 2.0],
        "yarn": [1.5, np.array([0, 1.5, 2]), -1, 1e30, 2 ** 40, np.array(["a", "b", "c"])],
        "semi_axes": [[0.1], [0.1, -0.1], np.ones((M, 3)), [[0.1, np.nan]] * M, [0.1, 1 + 1j]],
        "ref": [[0, 0, 0], [1.0, np.nan, 0], np.ones((M, 2)), [0, 0, 1 + 1j]],
        "contact_radius": [-0.1, 0.0, 1e300],
        "prestrain": [1.0, -1.0, 1e300, 5.0],
        "bending_factor": [0.0, -1.0, 1e300],
        "torsion_factor": [0.0, -1.0, 1e300],
    }
    return common + per.get(arg, [])


def periodic_bad():
    P = np.array([[3.0, 0, 0]])
    img = np.array([[0], [0], [1]])
    out = []
    for p in (np.array([3.0, 0, 0, 0, 0, 0]), np.ones((4, 3)), np.ones((1, 2)), P.astype(complex), P * 1e300,
              np.array([[np.nan, 0, 0]]), "P", [[3.0, 0, "x"]], np.array([[1.0, 0, 0], [2.0, 0, 0]])):
        out.append(("periods", dict(periods=p, images=img if np.size(p) == 3 else np.zeros((M, 2), int))))
    for i in (img + 0.5, img.astype(complex), np.full((M, 1), np.nan), img * 10 ** 9, np.zeros((M, 2), int),
              img.astype(str), None):
        out.append(("images", dict(periods=P, images=i)))
    return out


CASES = [(arg, {arg: v}) for arg in NAMES if arg not in ("periods", "images") for v in bad_values(arg)]
CASES += periodic_bad()


def build(changes):
    kw = dict(nodes=NODES, elements=ELEMENTS, **BASE)
    kw.update(changes)
    if "semi_axes" in changes:
        kw.pop("radius")
    return homtex.Frame(kw.pop("nodes"), kw.pop("elements"), **kw)


@pytest.mark.parametrize("arg, changes", CASES, ids=[f"{a}-{i}" for i, (a, _) in enumerate(CASES)])
def test_every_bad_frame_input_is_an_input_error_naming_it(arg, changes):
    try:
        f = build(changes)
    except homtex.InputError as err:
        assert NAMES[arg].lower() in str(err).lower(), (arg, str(err))
        return
    # accepted: only if the value was in fact fine (e.g. an integral float for yarn ids); then the
    # frame must be consistent and finite
    pytest.fail(f"{arg} = {changes[arg]!r} was accepted: {f}")


def _geometry_is_finite(f):
    for a in (f.nodes, f.length, f.R, f.A, f.Iy, f.Iz, f.J, f.k, f.G, f.element_vectors):
        assert np.all(np.isfinite(a))
    assert np.all(f.length > 0) and np.all(f.A > 0) and np.all(f.J > 0)


finite_or_not = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-10 ** 20, 10 ** 20),
                          st.booleans(), st.complex_numbers(), st.text(max_size=3), st.none())


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(arg=st.sampled_from(["radius", "E", "nu", "yarn", "contact_radius", "prestrain", "bending_factor",
                            "torsion_factor"]), value=finite_or_not)
def test_scalar_arguments_are_refused_by_name_or_give_finite_geometry(arg, value):
    try:
        f = build({arg: value})
    except homtex.InputError as err:
        assert NAMES[arg].lower() in str(err).lower(), (arg, value, str(err))
        return
    _geometry_is_finite(f)


@settings(max_examples=200, deadline=None)
@given(coords=st.lists(st.floats(allow_nan=True, allow_infinity=True, width=64), min_size=12, max_size=12))
def test_node_coordinates_are_refused_by_name_or_give_finite_geometry(coords):
    try:
        f = build({"nodes": np.array(coords).reshape(4, 3)})
    except homtex.InputError as err:
        assert "node" in str(err).lower() or "element" in str(err).lower() or "reference" in str(err).lower()
        return
    _geometry_is_finite(f)


@settings(max_examples=150, deadline=None)
@given(el=st.lists(st.one_of(st.integers(-5, 8), st.floats(-5, 8), st.just(float("nan"))), min_size=6, max_size=6))
def test_element_indices_are_refused_by_name_or_accepted(el):
    try:
        f = build({"elements": np.array(el, dtype=object if any(isinstance(x, float) for x in el) else None)
                   .reshape(3, 2)})
    except homtex.InputError as err:
        assert "element" in str(err).lower(), str(err)
        return
    _geometry_is_finite(f)


def test_integral_floats_are_accepted_as_indices():
    f = build({"yarn": np.array([0.0, 1.0, 1.0]), "elements": ELEMENTS.astype(float)})
    assert f.yarn.dtype == np.int64 and f.yarn.tolist() == [0, 1, 1]


# ------------------------------------------------------------------ cell files
import copy  # noqa: E402
import math  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

try:
    import tomllib
except ModuleNotFoundError:  # pragma: no cover
    import tomli as tomllib

CELLS = sorted((Path(__file__).resolve().parents[1] / "cells").glob("*.toml"))

BAD_LEAVES = ["a string", True, False, math.nan, math.inf, -math.inf, -1, 0, 0.0, -1e300, 1e300, 10 ** 18,
              2.5, [], [1, 2, 3], [[[[[[[[[[[[[[[[[[[[1]]]]]]]]]]]]]]]]]]]], {"x": 1}, 10_000, 1e-300,
              2 ** 70, 10 ** 400, [2 ** 70, 1]]   # beyond int64 and beyond double precision (tomllib reads them)
#: what replaces a whole table of a cell file (a table where a value belongs is among BAD_LEAVES)
BAD_TABLES = ["x", 1, 2.5, True, [1, 2], []]


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


def _set(d, path, value):
    for k in path[:-1]:
        d = d[k]
    if value is _DELETE:
        del d[path[-1]]
    else:
        d[path[-1]] = value


_DELETE = object()


def _frame_is_finite(cell):
    f = cell.frame
    for a in (f.nodes, f.length, f.R, f.A, f.Iy, f.Iz, f.J):
        assert np.all(np.isfinite(a))


@pytest.mark.parametrize("path", CELLS, ids=[p.stem for p in CELLS])
def test_mutated_cell_files_raise_cell_errors_or_build_finite_frames(path):
    """Every leaf of every shipped cell file replaced by every bad kind of value, deleted, or an
    unknown key added next to it: a CellError/InputError naming the table or key, or a cell whose
    frame is finite; never another exception, never longer than a few seconds."""
    from homtex.cells import Cell

    data = tomllib.loads(path.read_text())
    outcomes = {"error": 0, "accepted": 0}
    with homtex.set_options(max_elements=30_000):
        for leaf in _leaves(data):
            for value in [*BAD_LEAVES, _DELETE, "unknown"]:
                d = copy.deepcopy(data)
                if value == "unknown":
                    _set(d, leaf[:-1] + ("no_such_key",), 1.0)
                else:
                    _set(d, leaf, value)
                t0 = time.perf_counter()
                try:
                    cell = Cell(d, path)
                    cell.build()
                except homtex.InputError as err:
                    outcomes["error"] += 1
                    msg = str(err)
                    assert any(part in msg for part in leaf) or "[" in msg, (leaf, value, msg)
                else:
                    outcomes["accepted"] += 1
                    _frame_is_finite(cell)
                assert time.perf_counter() - t0 < 10.0, (leaf, value)
    assert outcomes["error"] > 0


@pytest.mark.parametrize("path", CELLS, ids=[p.stem for p in CELLS])
def test_a_value_in_place_of_a_table_is_a_cell_error(path):
    """Every table of every shipped cell file (nested ones included: [parameters.seam],
    [parameters.bars.pile], ...) replaced by a string, a number, a boolean or an array: a
    CellError naming the table and key (``seam = "x"`` raised AttributeError)."""
    from homtex.cells import Cell

    data = tomllib.loads(path.read_text())
    for table in _tables(data):
        for value in BAD_TABLES:
            d = copy.deepcopy(data)
            _set(d, table, value)
            try:
                Cell(d, path).build()
            except homtex.CellError as err:
                assert err.file == str(path)
                assert table[-1] in str(err), (table, value, str(err))


@pytest.mark.parametrize("key", ["gauge", "courses_per_cm", "thickness"])
@pytest.mark.parametrize("value", ["12", True, [12.0], {"v": 12}])
def test_spacer_numbers_refuse_strings_and_booleans(key, value):
    from homtex.cells import Cell

    data = tomllib.loads((Path(__file__).resolve().parents[1] / "cells" / "spacer_20mm.toml").read_text())
    data["parameters"][key] = value
    with pytest.raises(homtex.CellError, match=key):
        Cell(data).build()


def test_sizes_are_bounded_before_allocation():
    from homtex.cells import Cell

    data = tomllib.loads((Path(__file__).resolve().parents[1] / "cells" / "octet.toml").read_text())
    data["parameters"]["repeat"] = [10 ** 6, 10 ** 6, 10 ** 6]
    t0 = time.perf_counter()
    with pytest.raises(homtex.CellError, match=r"max_elements"):
        Cell(data).build()
    assert time.perf_counter() - t0 < 1.0
    spacer = tomllib.loads((Path(__file__).resolve().parents[1] / "cells" / "spacer_20mm.toml").read_text())
    spacer["parameters"]["bars"]["pile"]["lapping"] = "/".join(["1-0-2-3", "2-3-1-0"] * 5000) + "//"
    t0 = time.perf_counter()
    with pytest.raises(homtex.CellError, match=r"max_elements"):
        Cell(spacer).build()
    assert time.perf_counter() - t0 < 5.0


@pytest.mark.parametrize("key, value, limit", [("pile_segments", 2000, 100), ("elements_per_segment", 51, 50),
                                               ("pile_segments", 2 ** 70, 100)])
def test_spacer_resolution_is_bounded_before_building(key, value, limit):
    """pile_segments = 2000 passed the max_elements check (16 000 elements) and then spent 9 s and
    2.6 GB in a quadratic overlap search: the resolution keys are bounded up front."""
    from homtex.cells import Cell

    data = tomllib.loads((Path(__file__).resolve().parents[1] / "cells" / "spacer_20mm.toml").read_text())
    data["resolution"][key] = value
    t0 = time.perf_counter()
    with pytest.raises(homtex.CellError, match=rf"must be <= {limit}") as info:
        Cell(data).build()
    assert (info.value.table, info.value.key) == ("resolution", key)
    assert time.perf_counter() - t0 < 1.0
    data["resolution"][key] = limit          # the limit itself is allowed
    data["resolution"]["elements_per_segment" if key == "pile_segments" else "pile_segments"] = 1
    assert Cell(data).frame.n_elements > 0


def test_overlap_search_grows_with_the_elements_not_the_longest_one(monkeypatch):
    """yarn_overlaps searched element midpoints within the longest element's length: one long
    element among many short ones made every pair a candidate (quadratic). Its candidates are now
    the elements within a few contact radii, and it finds what a brute-force search finds."""
    from scipy.spatial import cKDTree

    from homtex.geometry import curves
    from homtex.geometry.curves import segment_distances, yarn_overlaps

    n = 2000
    x = np.linspace(0.0, 10.0, n + 1)
    chain = np.c_[x, np.zeros(n + 1), np.zeros(n + 1)]
    far = [[0.0, 5.0, 0.0], [100.0, 5.0, 0.0]]                  # one 100 mm element
    cross = [[3.0, -1.0, 0.05], [3.0, 1.0, 0.05]]                 # crosses the chain, 0.05 mm above
    nodes = np.vstack([chain, far, cross])
    els = np.vstack([np.c_[np.arange(n), np.arange(1, n + 1)], [[n + 1, n + 2]], [[n + 3, n + 4]]])
    fr = homtex.Frame(nodes, els, radius=0.05, E=1000.0, nu=0.3, yarn=np.r_[np.zeros(n), 1, 2].astype(int))
    found = []

    class Counting(cKDTree):
        def sparse_distance_matrix(self, other, r, **kw):
            out = super().sparse_distance_matrix(other, r, **kw)
            found.append(out.nnz)
            return out

    monkeypatch.setattr(curves, "cKDTree", Counting)
    ov = yarn_overlaps(fr)
    # the neighbours within a few radii along the chain (about 80 each), not all n^2 = 4e6 pairs
    assert sum(found) < 0.05 * fr.n_elements ** 2
    # brute force: every pair of different yarns
    a, b = np.triu_indices(fr.n_elements, 1)
    a, b = a[fr.yarn[a] != fr.yarn[b]], b[fr.yarn[a] != fr.yarn[b]]
    x0, d = fr.nodes[fr.elements[:, 0]], fr.element_vectors
    dist, _, _ = segment_distances(x0[a], d[a], x0[b], d[b])
    hit = fr.contact_radius[a] + fr.contact_radius[b] - dist > 1e-9
    assert sorted(zip(ov["element_a"].tolist(), ov["element_b"].tolist())) == sorted(zip(a[hit].tolist(),
                                                                                          b[hit].tolist()))
    assert len(ov) > 0 and set(ov["yarn_a"].tolist()) | set(ov["yarn_b"].tolist()) == {0, 2}


def test_deeply_nested_cell_file_is_a_cell_error(tmp_path):
    p = tmp_path / "deep.toml"
    p.write_text('[cell]\nname = "x"\ngenerator = "square"\n[parameters]\na = ' + "[" * 3000 + "1" + "]" * 3000 + "\n")
    with pytest.raises(homtex.CellError, match="nested too deeply"):
        homtex.load_cell(p)


@pytest.mark.parametrize("key, value, match", [("prestain", 0.3, "prestain"), ("prestrain", 1.5, "prestrain"),
                                               ("stitch_length", "4", "stitch_length"),
                                               ("yarn", "no_such_yarn", "yarn"), ("leg_elements", 2.5, "leg_elements")])
def test_seam_table_is_checked_when_the_cell_loads(key, value, match):
    """A typo or a bad value in [parameters.seam] is named at load time, not silently ignored."""
    from homtex.cells import Cell

    data = tomllib.loads((Path(__file__).resolve().parents[1] / "cells" / "spacer_20mm.toml").read_text())
    data["parameters"]["seam"][key] = value
    with pytest.raises(homtex.CellError, match=match):
        Cell(data).build()
