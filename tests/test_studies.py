"""The study scripts (studies/benchmarks, verification, experiments) do not rot.

Every script's ``--quick`` mode runs in a subprocess (as a user runs it: ``python SCRIPT --quick
--out DIR``, from an unrelated working directory) and writes a netCDF file that xarray opens and a
PNG chart; importing a script runs nothing; every study file (studies/configs) loads.
"""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

ROOT = Path(__file__).resolve().parents[1]
STUDIES = ROOT / "studies"
FOLDERS = ("benchmarks", "verification", "experiments")
SCRIPTS = sorted(p for folder in FOLDERS for p in (STUDIES / folder).glob("*.py") if not p.name.startswith("_"))
CONFIGS = sorted((STUDIES / "configs").glob("*.toml"))
# optional packages a script needs beyond homtex's own dependencies
NEEDS = {"bench_core.py": ("psutil",), "bench_corotational.py": ("openseespy.opensees",)}
# scripts whose quick mode a test runs in-process with physics asserted (tests/test_contact_studies.py):
# not run a second time here
IN_PROCESS = {"contact_enforcement.py"}
QUICK = [p for p in SCRIPTS if p.name not in IN_PROCESS]


def _id(p: Path) -> str:
    return f"{p.parent.name}/{p.stem}"


def _env() -> dict:
    """The environment of a script run: the repository first on the path, so that the scripts use
    this checkout whether homtex is installed or not; one thread (unless set)."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), *filter(None, [env.get("PYTHONPATH")])])
    env["MPLBACKEND"] = "Agg"
    # one thread each: the quick runs are small, and the test machine may be shared
    for key in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        env.setdefault(key, "1")
    return env


def test_layout():
    assert len(SCRIPTS) >= 20
    assert {p.parent.name for p in SCRIPTS} == set(FOLDERS)
    assert [p.name for p in STUDIES.glob("*.py")] == ["_common.py"], "scripts live in the three folders"
    assert not list(STUDIES.glob("*.toml")), "study files live in studies/configs"
    readme = (STUDIES / "README.md").read_text()
    for p in SCRIPTS:
        assert f"{p.parent.name}/{p.name}" in readme, f"{_id(p)} is not listed in studies/README.md"


@pytest.mark.slow
@pytest.mark.parametrize("script", QUICK, ids=_id)
def test_quick_mode(script, tmp_path):
    for mod in NEEDS.get(script.name, ()):
        pytest.importorskip(mod)
    out = tmp_path / "out"
    t0 = time.perf_counter()
    res = subprocess.run([sys.executable, str(script), "--quick", "--out", str(out)], cwd=tmp_path, env=_env(),
                         capture_output=True, text=True, timeout=600)
    seconds = time.perf_counter() - t0
    assert res.returncode == 0, f"{_id(script)} --quick failed:\n{res.stdout[-3000:]}\n{res.stderr[-3000:]}"
    ncs, pngs = sorted(out.glob("*.nc")), sorted(out.glob("*.png"))
    assert ncs, f"{_id(script)} --quick wrote no netCDF file"
    assert pngs, f"{_id(script)} --quick wrote no chart"
    for nc in ncs:
        with xr.open_dataset(nc) as ds:
            assert ds.data_vars, f"{nc.name} holds no variables"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"], "the script wrote outside --out"
    print(f"{_id(script)} --quick: {seconds:.1f} s")


@pytest.mark.parametrize("script", SCRIPTS, ids=_id)
def test_import_runs_nothing(script, tmp_path, monkeypatch):
    """Importing a script (its code under ``if __name__ == "__main__":``) computes and writes nothing."""
    import numpy  # noqa: F401  - the scripts' module-level imports, not their work, are
    import scipy.optimize  # noqa: F401
    import scipy.sparse  # noqa: F401

    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "path", list(sys.path))
    monkeypatch.setattr(sys, "argv", [str(script)])
    monkeypatch.setattr(sys, "dont_write_bytecode", True)
    name = f"_study_{script.stem}"
    spec = importlib.util.spec_from_file_location(name, script)
    mod = importlib.util.module_from_spec(spec)
    t0 = time.perf_counter()
    try:
        spec.loader.exec_module(mod)
        seconds = time.perf_counter() - t0
    finally:
        sys.modules.pop(name, None)
    assert seconds < 2.0, f"importing {_id(script)} took {seconds:.1f} s"
    assert not list(tmp_path.iterdir()), f"importing {_id(script)} wrote {[p.name for p in tmp_path.iterdir()]}"
    assert callable(getattr(mod, "main", None)), f"{_id(script)} has no main()"
    doc = mod.__doc__ or ""
    assert "--quick" in doc and f"python studies/{script.parent.name}/{script.name}" in doc, \
        f"{_id(script)}: the docstring says what it measures and how to run it (and --quick)"


def test_quick_never_writes_into_docs(tmp_path):
    script = STUDIES / "benchmarks" / "bench_rom.py"
    res = subprocess.run([sys.executable, str(script), "--quick", "--out", str(ROOT / "docs" / "studies")],
                         cwd=tmp_path, env=_env(), capture_output=True, text=True, timeout=120)
    assert res.returncode != 0 and "docs" in res.stderr
    assert not (ROOT / "docs" / "studies" / "bench_rom.nc").exists()


@pytest.mark.parametrize("config", CONFIGS, ids=lambda p: p.stem)
def test_study_files_load(config, tmp_path):
    """Every shipped study file loads; one that needs an input file made by another command first
    (macro_seams: the unseamed curve) names that file when it is missing and loads with it."""
    import shutil

    import homtex
    import homtex.output.io
    from homtex.study.files import load_study

    try:
        st = load_study(config)
    except homtex.StudyError as err:
        assert "curve_file" in str(err), str(err)
        copy = tmp_path / "studies" / "configs" / config.name   # as in the checkout: results/ two levels up
        copy.parent.mkdir(parents=True)
        shutil.copy(config, copy)
        text = copy.read_text().replace("../../cells/", str(config.parents[2] / "cells") + "/")
        # the file the recipe's command writes (`homtex compress CELL ... --out results/compress`,
        # from the checkout's root) is the one curve_file names
        recipe = next(ln for ln in config.read_text().splitlines() if "homtex compress" in ln).split()
        cell_arg, out_arg = recipe[recipe.index("compress") + 1], recipe[recipe.index("--out") + 1]
        from homtex.app.paths import stem_of
        curve = tmp_path / out_arg / f"{stem_of(homtex.load_cell(cell_arg))}_compression.nc"
        curve.parent.mkdir(parents=True)
        e = np.linspace(0.02, 0.5, 25)
        homtex.output.io.write_netcdf(xr.Dataset({"stress": ("strain", 40.0 * e, {"units": "kPa"})},
                                                 coords={"strain": e}), curve)
        copy.write_text(text)
        st = load_study(copy)
    assert st.cell_path is None or Path(st.cell_path).exists()
    assert st.points
