"""The homtex command: the main job's quick variant writes what it says, errors are clean."""

import subprocess
import sys

import numpy as np
import xarray as xr

from homtex.cli import main


def test_run_quick_writes_dataset_and_chart(tmp_path):
    assert main(["run", "--quick", "--out", str(tmp_path)]) == 0
    ds = xr.open_dataset(tmp_path / "lattice_demo.nc")
    assert (tmp_path / "lattice_demo.png").stat().st_size > 10_000
    assert float(ds["force"]) > 0                      # compression resisted
    assert float(ds["max_difference"].max()) < 1e-7    # amg, direct and cg agree
    for v in ds.data_vars.values():
        assert "units" in v.attrs and "long_name" in v.attrs
    ds.close()


def test_bad_input_is_a_message_not_a_traceback(tmp_path):
    p = subprocess.run([sys.executable, "-m", "homtex.cli", "seam", str(tmp_path / "missing.toml"),
                        "--distance", "24"], capture_output=True, text=True)
    assert p.returncode == 2
    assert "Traceback" not in p.stderr and "error" in p.stderr


def test_homogenize_command_matches_api_and_plots(tmp_path, capsys):
    import homtex

    cell = "cells/square.toml"
    assert main(["homogenize", cell, "--out", str(tmp_path)]) == 0
    (nc,) = tmp_path.glob("*.nc")
    with xr.open_dataset(nc) as ds:
        C = ds["C"].values
    np.testing.assert_allclose(C, homtex.homogenize(homtex.load_cell(cell).frame).C, rtol=1e-10)
    assert main(["plot", str(nc), "--out", str(tmp_path / "p.png")]) == 0
    assert (tmp_path / "p.png").stat().st_size > 5_000


def test_malformed_cell_file_names_key(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text('[cell]\nname = "x"\ngenerator = "square"\n[parameters]\na = -1.0\n'
                   '[yarns.s]\nsection = "circle"\nradius = 0.1\nE = 1.0\nnu = 0.3\nsource = "t"\n')
    p = subprocess.run([sys.executable, "-m", "homtex.cli", "homogenize", str(bad)],
                       capture_output=True, text=True)
    assert p.returncode == 2 and "Traceback" not in p.stderr
    assert "bad.toml" in p.stderr and "[parameters]" in p.stderr and "'a'" in p.stderr
