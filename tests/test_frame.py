"""Frame validation: every bad input raises InputError naming the culprit."""

import numpy as np
import pytest

import homtex

NODES = np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0], [2, 1, 0]])
ELEMENTS = np.array([[0, 1], [1, 2], [2, 3]])
KW = dict(radius=0.1, E=1000.0, nu=0.3)


def make(nodes=NODES, elements=ELEMENTS, **kw):
    return homtex.Frame(nodes, elements, **(KW | kw))


def test_valid_frame_and_properties():
    f = make(yarn=[4, 4, 5])
    assert f.n_nodes == 4 and f.n_elements == 3 and f.ndof == 24
    np.testing.assert_allclose(f.length, [1, 1, 1])
    # rotation matrices are orthonormal with e1 along the element
    np.testing.assert_allclose(np.einsum("eij,ekj->eik", f.R, f.R), np.broadcast_to(np.eye(3), (3, 3, 3)), atol=1e-15)
    np.testing.assert_allclose(f.R[2, 0], [0, 1, 0])


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_node(bad):
    nodes = NODES.copy()
    nodes[2, 1] = bad
    with pytest.raises(homtex.InputError, match=r"node 2 "):
        make(nodes)


def test_zero_length_element():
    nodes = NODES.copy()
    nodes[3] = nodes[2]
    with pytest.raises(homtex.InputError, match=r"element 2 .*zero length"):
        make(nodes, yarn=[0, 0, 7])


def test_zero_length_element_names_yarn():
    nodes = NODES.copy()
    nodes[3] = nodes[2]
    with pytest.raises(homtex.InputError, match=r"yarn 7"):
        make(nodes, yarn=[0, 0, 7])


@pytest.mark.parametrize("el", [[[0, 1], [1, 2], [1, 0]], [[0, 1], [1, 2], [0, 1]]])
def test_duplicate_elements(el):
    with pytest.raises(homtex.InputError, match=r"elements 0 and 2 are duplicates"):
        make(elements=np.array(el))


@pytest.mark.parametrize("el, culprit", [([[0, 1], [1, 4]], "element 1"), ([[0, 1], [-1, 2]], "element 1")])
def test_index_out_of_range(el, culprit):
    with pytest.raises(homtex.InputError, match=culprit + r" refers to node"):
        make(elements=np.array(el))


@pytest.mark.parametrize("name, value, culprit", [
    ("radius", [0.1, -0.2, 0.1], "radius of element 1"),
    ("radius", [0.1, 0.1, 0.0], "radius of element 2"),
    ("E", [1000.0, 0.0, 1.0], "E of element 1"),
    ("E", -5.0, "E of element 0"),
    ("nu", [0.3, 0.3, 0.5], "nu of element 2"),
    ("nu", -1.0, "nu of element 0"),
    ("semi_axes", [[0.1, 0.1], [0.1, -0.1], [0.2, 0.1]], r"semi-axis b \(semi_axes\[:, 1\]\) of element 1"),
])
def test_bad_section_or_material(name, value, culprit):
    kw = {name: value}
    if name == "semi_axes":
        kw["radius"] = None
    with pytest.raises(homtex.InputError, match=culprit):
        make(**kw)


def test_reference_vector_parallel():
    ref = np.array([[0, 0, 1.0], [0, 0, 1.0], [0, 3.0, 0]])   # element 2 runs along y
    with pytest.raises(homtex.InputError, match=r"reference vector .* of element 2 .*parallel"):
        make(ref=ref)


def test_periodic_inputs():
    P = np.array([[3.0, 0, 0]])
    f = make(periods=P, images=np.array([[0], [0], [1]]))
    assert f.dim_periodic == 1
    np.testing.assert_allclose(f.element_vectors[2], [3, 1, 0])
    with pytest.raises(homtex.InputError, match="images must have shape"):
        make(periods=P, images=np.zeros((2, 1), int))
    with pytest.raises(homtex.InputError, match="not linearly independent"):
        make(periods=np.array([[1.0, 0, 0], [2.0, 0, 0]]), images=np.zeros((3, 2), int))
    # the same periodic strut written backwards is a duplicate
    nodes = np.array([[0.0, 0, 0], [0.5, 0.2, 0]])
    with pytest.raises(homtex.InputError, match="duplicates"):
        homtex.Frame(nodes, [[0, 0], [0, 0]], periods=P, images=[[1], [-1]], **KW)


def test_bad_supports_and_loads():
    f = make()
    with pytest.raises(homtex.InputError, match="node 9"):
        homtex.solve_static(f, {9: "all"}, None)
    with pytest.raises(homtex.InputError, match="DOF"):
        homtex.solve_static(f, {0: [0, 7]}, None)
    with pytest.raises(homtex.InputError, match=r"loads\[1\]"):
        homtex.solve_static(f, {0: "all"}, {1: (1.0, 2.0)})
    with pytest.raises(homtex.InputError, match=r"loads\[1\]"):
        homtex.solve_static(f, {0: "all"}, {1: (np.nan, 0, 0, 0, 0, 0)})
    with pytest.raises(homtex.InputError, match="solver"):
        homtex.solve_static(f, {0: "all"}, {1: (0, 1, 0, 0, 0, 0)}, solver="magic")
