"""The contact enforcement study's quick mode, in-process, with its physics asserted (tests/test_studies.py
runs every other script's quick mode)."""

import importlib.util
from pathlib import Path

import pytest

STUDIES = Path(__file__).resolve().parents[1] / "studies"


def load(name):
    spec = importlib.util.spec_from_file_location(name, next(STUDIES.glob(f"*/{name}.py")))
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.mark.slow
def test_contact_enforcement_quick(tmp_path):
    mod = load("contact_enforcement")
    ds = mod.run(tmp_path, quick=True, docs=False)
    assert (tmp_path / "contact_enforcement.nc").exists() and (tmp_path / "contact_enforcement.png").exists()
    # the barrier with the CCD converges on every quick run and never penetrates
    b = ds.sel(enforcement="barrier", step="ccd")
    assert bool(b.converged.all())
    assert "units" in ds.gap_error.attrs and "problem" in ds.dims
    assert "converged" in mod.summary(ds)

