import numpy as np
import pytest

import homtex


@pytest.fixture(autouse=True, scope="session")
def _private_result_cache(tmp_path_factory):
    """The result cache (homtex.cache) of the test session lives in a folder of its own: tests
    neither read a user's cached results nor leave theirs behind."""
    import os

    old = os.environ.get("HOMTEX_CACHE_DIR")
    os.environ["HOMTEX_CACHE_DIR"] = str(tmp_path_factory.mktemp("homtex_cache"))
    yield
    if old is None:
        os.environ.pop("HOMTEX_CACHE_DIR", None)
    else:
        os.environ["HOMTEX_CACHE_DIR"] = old


def line_frame(n_el, L=100.0, direction=(1.0, 0.0, 0.0), **kw):
    """A straight beam of n_el elements from the origin along ``direction``."""
    d = np.asarray(direction, float)
    d = d / np.linalg.norm(d)
    nodes = np.linspace(0.0, L, n_el + 1)[:, None] * d
    el = np.column_stack([np.arange(n_el), np.arange(1, n_el + 1)])
    return homtex.Frame(nodes, el, **kw)


def random_frame(seed=0, n=12, extra=10, ellipse=False):
    """A connected random 3D frame (a tree plus extra edges), varied sections."""
    rng = np.random.default_rng(seed)
    nodes = rng.uniform(0, 10, (n, 3))
    el = [(i, int(rng.integers(0, i))) for i in range(1, n)]
    have = {tuple(sorted(e)) for e in el}
    while len(el) < n - 1 + extra:
        a, b = (int(x) for x in rng.integers(0, n, 2))
        if a != b and tuple(sorted((a, b))) not in have:
            have.add(tuple(sorted((a, b))))
            el.append((a, b))
    m = len(el)
    kw = dict(E=rng.uniform(1e3, 5e3, m), nu=rng.uniform(0.1, 0.45, m),
              yarn=np.arange(m) % 3)
    if ellipse:
        kw["semi_axes"] = rng.uniform(0.1, 0.5, (m, 2))
    else:
        kw["radius"] = rng.uniform(0.1, 0.5, m)
    kw["ref"] = rng.normal(size=(m, 3))
    return homtex.Frame(nodes, np.array(el), **kw)


@pytest.fixture
def rng():
    return np.random.default_rng(1234)
