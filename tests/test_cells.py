"""Cell files: loading, validation errors naming file/table/key, replace, attrs."""

from pathlib import Path

import numpy as np
import pytest

import homtex
from homtex import cells
from homtex.cells import Cell, CellError, load_cell
from homtex.geometry.lattices import lattice_frame

CELLS = Path(__file__).resolve().parents[1] / "cells"
LATTICE_FILES = ["honeycomb", "reentrant_honeycomb", "square", "triangular", "octet", "bcc",
                 "simple_cubic"]

GOOD = """
[cell]
name = "hc"
generator = "honeycomb"
description = "test"

[parameters]
h = 1.2
l = 1.0
theta = -25.0

[yarns.wall]
section = "ellipse"
semi_axes = [0.07, 0.05]
E = 3000.0
nu = 0.3
contact_radius = 0.08
source = "test"

[resolution]
elements_per_strut = 1
"""


def write(tmp_path, text, name="cell.toml"):
    p = tmp_path / name
    p.write_text(text)
    return p


@pytest.mark.parametrize("name", LATTICE_FILES)
def test_shipped_lattice_cells_load(name):
    cell = load_cell(CELLS / f"{name}.toml")
    assert isinstance(cell.frame, homtex.Frame)
    assert cell.frame.dim_periodic in (2, 3)
    assert all(y.source for y in cell.yarns.values())
    res = homtex.homogenize(cell.frame)
    assert np.linalg.eigvalsh(res.C).min() > 0
    assert cell.groups["struts"].shape == (cell.frame.n_elements,)


def test_honeycomb_file_matches_closed_form(tmp_path):
    from test_periodic import honeycomb_closed_form

    cell = load_cell(write(tmp_path, GOOD))
    assert cell.name == "hc" and cell.generator == "honeycomb" and cell.description == "test"
    y = cell.yarns["wall"]
    assert (y.a, y.b, y.E, y.nu, y.rc) == (0.07, 0.05, 3000.0, 0.3, 0.08)
    assert np.allclose(cell.frame.contact_radius, 0.08)
    got = homtex.homogenize(cell.frame).engineering_constants()
    want = honeycomb_closed_form(1.2, 1.0, -25.0, 0.07, 0.05)
    for k, v in want.items():
        assert got[k] == pytest.approx(v, rel=1e-6)


BAD = [
    # (description, replace (old, new), table, key, message fragment)
    ("missing key", ("semi_axes = [0.07, 0.05]\n", ""), "yarns.wall", "semi_axes", "missing key"),
    ("wrong type", ("E = 3000.0", 'E = "3000"'), "yarns.wall", "E", "must be a number, got a string"),
    ("negative size", ("semi_axes = [0.07, 0.05]", "semi_axes = [0.07, -0.05]"), "yarns.wall",
     "semi_axes", "must be > 0"),
    ("bad nu", ("nu = 0.3", "nu = 0.5"), "yarns.wall", "nu", "must be < 0.5"),
    ("unknown generator", ('generator = "honeycomb"', 'generator = "honeycombe"'), "cell",
     "generator", "unknown generator 'honeycombe'"),
    ("missing name", ('name = "hc"\n', ""), "cell", "name", "missing key"),
    ("unknown yarn key", ("source = \"test\"", "source = \"test\"\nradius_typo = 1.0"), "yarns.wall",
     "radius_typo", "unknown key"),
    ("ellipse with radius", ("semi_axes = [0.07, 0.05]", "radius = 0.1"), "yarns.wall", "radius",
     "semi_axes"),
    ("bad section", ('section = "ellipse"', 'section = "square"'), "yarns.wall", "section",
     "must be one of"),
    ("missing source", ('source = "test"\n', ""), "yarns.wall", "source", "missing key"),
    ("zero bending factor", ('source = "test"', 'source = "test"\nbending_factor = 0.0'), "yarns.wall",
     "bending_factor", "must be > 0"),
    ("negative torsion factor", ('source = "test"', 'source = "test"\ntorsion_factor = -2.0'), "yarns.wall",
     "torsion_factor", "must be > 0"),
    ("theta zero", ("theta = -25.0", "theta = 0.0"), "parameters", "theta", "not independent"),
    ("collapsed cell", ("h = 1.2", "h = 0.3"), "parameters", "theta", "not independent"),
    ("negative wall", ("h = 1.2", "h = -1.2"), "parameters", "h", "must be > 0, got -1.2"),
    ("parameter typo", ("h = 1.2", "hh = 1.2"), "parameters", "hh", "unknown key"),
    ("resolution type", ("elements_per_strut = 1", "elements_per_strut = 1.5"), "resolution",
     "elements_per_strut", "must be an integer"),
    ("resolution value", ("elements_per_strut = 1", "elements_per_strut = 0"), "resolution",
     "elements_per_strut", "must be >= 1"),
]


@pytest.mark.parametrize("what,edit,table,key,fragment", BAD, ids=[b[0] for b in BAD])
def test_malformed_cell_names_file_table_key(tmp_path, what, edit, table, key, fragment):
    old, new = edit
    assert old in GOOD
    p = write(tmp_path, GOOD.replace(old, new, 1))
    with pytest.raises(CellError) as info:
        load_cell(p)
    err = info.value
    assert isinstance(err, homtex.InputError)
    assert (err.file, err.table, err.key) == (str(p), table, key)
    assert str(err).startswith(f"{p}: [{table}] key '{key}': ")
    assert fragment in str(err)


def test_message_format_negative_radius(tmp_path):
    text = GOOD.replace("section = \"ellipse\"\nsemi_axes = [0.07, 0.05]",
                        "section = \"circle\"\nradius = -0.1")
    p = write(tmp_path, text)
    with pytest.raises(CellError) as info:
        load_cell(p)
    assert str(info.value) == f"{p}: [yarns.wall] key 'radius': must be > 0, got -0.1"


LATTICE = """
[cell]
name = "explicit"
generator = "lattice"

[parameters]
basis = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]
points = [[0.0, 0.0, 0.0]]
struts = [[0, 0], [0, 0]]
images = [[1, 0], [0, 1]]

[yarns.strut]
section = "circle"
radius = 0.05
E = 3000.0
nu = 0.3
source = "test"
"""


def test_explicit_lattice_and_dependent_vectors(tmp_path):
    cell = load_cell(write(tmp_path, LATTICE))
    ref = lattice_frame("square", a=1.0, radius=0.05, E=3000.0, nu=0.3)
    C1 = homtex.homogenize(cell.frame, solver="direct").C
    C2 = homtex.homogenize(ref, solver="direct").C
    assert np.allclose(C1, C2, rtol=1e-12, atol=0)
    p = write(tmp_path, LATTICE.replace("[0.0, 1.0, 0.0]]", "[2.0, 0.0, 0.0]]"), "dep.toml")
    with pytest.raises(CellError, match=r"\[parameters\] key 'basis': .*not linearly independent") as info:
        load_cell(p)
    assert info.value.file == str(p)
    p = write(tmp_path, LATTICE.replace("images = [[1, 0], [0, 1]]", "images = [[1, 0]]"), "img.toml")
    with pytest.raises(CellError, match=r"\[parameters\] key 'images': must have shape 2x2"):
        load_cell(p)


def test_file_level_errors(tmp_path):
    with pytest.raises(CellError, match="no such file"):
        load_cell(tmp_path / "missing.toml")
    p = write(tmp_path, "[cell\nname = 1", "broken.toml")
    with pytest.raises(CellError, match=rf"{p}: not valid TOML"):
        load_cell(p)
    p = write(tmp_path, GOOD + "\n[extra]\nx = 1\n", "extra.toml")
    with pytest.raises(CellError, match=r"\[extra\]: unknown table"):
        load_cell(p)
    p = write(tmp_path, GOOD.split("[yarns.wall]")[0], "noyarn.toml")
    with pytest.raises(CellError, match="missing table"):
        load_cell(p)
    two = GOOD + '\n[yarns.other]\nsection = "circle"\nradius = 0.1\nE = 1.0\nnu = 0.2\nsource = "x"\n'
    p = write(tmp_path, two, "two.toml")
    with pytest.raises(CellError, match=r"\[parameters\] key 'yarn': .*name the one"):
        load_cell(p)
    cell = load_cell(write(tmp_path, two.replace("theta = -25.0", 'theta = -25.0\nyarn = "other"'), "t.toml"))
    assert np.allclose(cell.frame.E, 1.0)


def test_unavailable_generator_is_a_clear_error(tmp_path, monkeypatch):
    monkeypatch.setitem(cells.GENERATORS, "ghost", "homtex.geometry.no_such_module:build_cell")
    p = write(tmp_path, GOOD.replace('generator = "honeycomb"', 'generator = "ghost"'))
    with pytest.raises(CellError, match=r"\[cell\] key 'generator': generator 'ghost' .* is not available"):
        load_cell(p)
    assert cells.GENERATORS["spacer"] == "homtex.geometry.spacer:build_cell"


def test_replace_and_attrs(tmp_path):
    p = write(tmp_path, GOOD)
    cell = load_cell(p)
    new = cell.replace(**{"yarns.wall.E": 1500.0, "resolution.elements_per_strut": 3,
                          "parameters.theta": 30.0})
    assert new.frame.n_elements == 3 * cell.frame.n_elements
    assert np.allclose(new.frame.E, 1500.0) and np.allclose(cell.frame.E, 3000.0)
    assert new.parameters["theta"] == 30.0 and cell.parameters["theta"] == -25.0
    assert new.path == cell.path
    circ = cell.replace(**{"yarns.wall.section": "circle", "yarns.wall.semi_axes": None,
                           "yarns.wall.radius": 0.06})
    assert np.allclose(circ.frame.a, 0.06) and np.allclose(circ.frame.b, 0.06)
    with pytest.raises(CellError) as info:
        cell.replace(**{"yarns.wall.E": -1.0})
    assert (info.value.file, info.value.table, info.value.key) == (str(p), "yarns.wall", "E")
    with pytest.raises(CellError, match="no table"):
        cell.replace(**{"yarns.pile.radius": 0.1})
    with pytest.raises(CellError, match="table.key"):
        cell.replace(**{"radius": 0.1})
    attrs = cell.attrs()
    assert attrs["yarns.wall.E"] == 3000.0 and attrs["cell.generator"] == "honeycomb"
    assert attrs["yarns.wall.semi_axes"] == "[0.07, 0.05]"
    assert attrs["cell.path"] == str(p)
    assert all(isinstance(v, (str, float, int)) for v in attrs.values())
    d = cell.to_dict()
    d["parameters"]["h"] = 99.0
    assert cell.parameters["h"] == 1.2
    again = Cell(cell.to_dict(), path="memory")
    assert again.frame.n_elements == cell.frame.n_elements


def test_endless_or_huge_files_are_refused_before_reading(tmp_path):
    """A cell path to a device that never ends (/dev/zero) or a file over the 10 MB limit is a
    CellError naming the file, before anything is read (reading /dev/zero filled the memory)."""
    from homtex.validate import MAX_FILE_BYTES

    if Path("/dev/zero").exists():
        with pytest.raises(CellError, match="not a regular file") as info:
            load_cell("/dev/zero")
        assert info.value.file == "/dev/zero"
    big = tmp_path / "big.toml"
    with open(big, "wb") as fh:          # sparse: no disk space or time spent
        fh.truncate(MAX_FILE_BYTES + 1)
    with pytest.raises(CellError, match=r"larger than the 10.5 MB") as info:
        load_cell(big)
    assert info.value.file == str(big)
    ok = write(tmp_path, GOOD)           # the limit leaves ordinary files alone
    assert load_cell(ok).frame.n_elements > 0


@pytest.mark.parametrize("old, new, key", [
    ("h = 1.2", "h = 1" + "0" * 400, "h"),
    ("theta = -25.0", "theta = -25.0\nrepeat = [100000000000000000000, 1]", "repeat"),
])
def test_integers_beyond_64_bits_are_cell_errors(tmp_path, old, new, key):
    """TOML integers have no size limit in tomllib: one beyond double precision (float() raised
    OverflowError) or beyond int64 in an integer array (numpy raised OverflowError) is a CellError
    naming the file, table and key."""
    p = write(tmp_path, GOOD.replace(old, new))
    with pytest.raises(CellError) as info:
        load_cell(p)
    assert (info.value.file, info.value.table, info.value.key) == (str(p), "parameters", key)
    assert len(str(info.value)) < 400          # the 400 digits are not repeated in the message


def test_a_value_where_a_table_belongs_is_a_cell_error(tmp_path):
    """``[parameters] seam = "x"`` raised AttributeError ('str' object has no attribute 'get')."""
    text = (CELLS / "spacer_20mm.toml").read_text()
    start, end = text.index("[parameters.seam]"), text.index("[parameters.bars.top_pillar]")
    p = tmp_path / "spacer.toml"
    p.write_text((text[:start] + text[end:]).replace("thickness = 20.0", 'thickness = 20.0\nseam = "x"', 1))
    with pytest.raises(CellError) as info:
        load_cell(p)
    assert (info.value.file, info.value.table, info.value.key) == (str(p), "parameters", "seam")
    assert "must be a table" in str(info.value)
