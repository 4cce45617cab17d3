"""The homtex command: the main job's quick variant writes what it says, errors are clean."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from homtex.app.cli import main


@pytest.mark.slow
def test_run_quick_writes_the_paper_study(tmp_path):
    """The main job (quick variant: seam cells of one to three fabric repeats on the engine) end to
    end: every stage writes a self-describing Dataset and a chart, and the numbers in them obey the
    physics they claim."""
    assert main(["run", "--quick", "--out", str(tmp_path)]) == 0
    for name in ("lattice_demo", "unseamed_compression", "cushions", "macro_curves",
                 "seamed_yarn_vs_macro", "strip_vs_macro", "speed_accuracy"):
        assert (tmp_path / f"{name}.png").stat().st_size > 10_000, name
        with xr.open_dataset(tmp_path / f"{name}.nc") as ds:
            for v in ds.data_vars.values():
                assert "units" in v.attrs and "long_name" in v.attrs, (name, v.name)
            for c in ds.coords.values():
                assert "units" in c.attrs and "long_name" in c.attrs, (name, c.name)
            assert ds.attrs["homtex_kind"] and ds.attrs["cell_name"], name
        assert main(["plot", str(tmp_path / f"{name}.nc"), "--out", str(tmp_path / f"replot_{name}.png")]) == 0
    with xr.open_dataset(tmp_path / "lattice_demo.nc") as ds:
        assert float(ds["force"]) > 0                      # compression resisted
        assert float(ds["max_difference"].max()) < 1e-7    # amg, direct and cg agree
    with xr.open_dataset(tmp_path / "unseamed_compression.nc") as ds:
        # the engine: no small-rotation bound to shade, the curve reaches the plan's end
        assert ds.attrs["validity_strain"] == 1.0 and float(ds.strain[-1]) == pytest.approx(0.36)
        assert np.isfinite(ds.stress.values).all() and float(ds.stress[-1]) > 0
    with xr.open_dataset(tmp_path / "cushions.nc") as ds:
        assert ds.attrs["yarn_geometry"] == "nonlinear"
        h = ds.cushion_height_yarn.values
        # wider seam spacing, higher cushions, all below the unseamed 20 mm
        assert h[0] < h[1] < h[2] < 20.0
        # the low needle-thread setting (15 % of the paper's 40 %) pinches less and shortens the legs less
        assert float(ds.prestrain_yarn[3]) == pytest.approx(float(ds.prestrain_yarn[2]) * 15 / 40)
        assert h[3] > h[2]
        assert float(ds.leg_loss_near_seam_yarn[3]) < float(ds.leg_loss_near_seam_yarn[2])
        # the foundation model is calibrated on 24 mm: it reproduces 14.33 mm there
        assert float(ds.cushion_height_paper_simulation.sel(paper_distance=24.0)) == 14.33
    with xr.open_dataset(tmp_path / "seamed_yarn_vs_macro.nc") as ds:
        # the plate carries nothing before it reaches the sewn cushion (its first contact within one level)
        w, s = ds.plate_displacement.values, ds.stress_yarn.values
        gap = 20.0 - ds.attrs["sewn_thickness_mm"]
        assert gap > 2.0 and (s[w < gap - 0.4] < 1e-3 * s.max()).all() and s[-1] > 0
        assert ds.attrs["speedup"] > 1000
    with xr.open_dataset(tmp_path / "macro_curves.nc") as ds:
        F = ds.force.fillna(0.0)
        w = ds.plate_displacement.values
        # more seams: lower cushions, the punch meets them later, so the force is lower early on
        early = w <= 4.0
        f = {sp: float(F.sel(specimen=sp).values[early].sum()) for sp in ds.specimen.values}
        assert f["no seams"] > f["d=12.75"] > f["d=8.5"] >= f["d=4.25"]
    with xr.open_dataset(tmp_path / "strip_vs_macro.nc") as ds:
        # the strip's seams are sewn with different pre-strains, so its cushions differ
        # (a cushion lies between two seams: with three seams of 1.1 / 0.9 / 1.0 x the stitch no two
        # cushions have the same pair)
        assert ds.attrs["seams"] == 3 and np.ptp(ds.cushion_height_strip.values) > 0.05
    with xr.open_dataset(tmp_path / "speed_accuracy.nc") as ds:
        for q in set(ds.question.values):
            sel = ds.question.values == q
            ref = ds.error.values[sel] == 0
            assert ref.sum() == 1, q                        # one reference per question
            # the macro layer answers in a fraction of the yarn-level reference's time
            macro = np.array(["macro" in str(m) for m in ds.model.values[sel]])
            if macro.any():
                assert ds.seconds.values[sel][macro].max() < 1e-2 * ds.seconds.values[sel][ref][0]
    text = (tmp_path / "summary.md").read_text()
    assert "Cushion heights" in text and "Stage times" in text and "Strip of 3" in text


def test_background_job_returns_its_result_and_is_stopped_on_close():
    """The main job's second process (the strip, sewn and pressed while the other stages run):
    its result comes back, and closing it (an error in the main process) stops a running job at
    once instead of waiting minutes for it."""
    import functools
    import time

    from homtex.app.main_job import _Background

    job = _Background(dict, {"seam_distance": 18.0, "factors": (1.1, 0.9)})
    assert job.result() == {"seam_distance": 18.0, "factors": (1.1, 0.9)}
    job = _Background(functools.partial(time.sleep, 120.0), {})
    t0 = time.perf_counter()
    job.close()
    assert time.perf_counter() - t0 < 10.0


def test_bad_input_is_a_message_not_a_traceback(tmp_path):
    p = subprocess.run([sys.executable, "-m", "homtex.app.cli", "seam", str(tmp_path / "missing.toml"),
                        "--distance", "24"], capture_output=True, text=True)
    assert p.returncode == 2
    assert "Traceback" not in p.stderr and "error" in p.stderr


def test_homogenize_command_matches_api_and_plots(tmp_path, capsys):
    import homtex

    cell = "cells/square.toml"
    assert main(["homogenize", cell, "--out", str(tmp_path)]) == 0
    (nc,) = tmp_path.glob("*.nc")
    assert nc.name == "square_homogenized.nc"
    with xr.open_dataset(nc) as ds:
        C = ds["C"].values
        for c in ds.coords.values():      # units and long names on the coordinates too
            assert "units" in c.attrs and "long_name" in c.attrs, c.name
    np.testing.assert_allclose(C, homtex.homogenize(homtex.load_cell(cell).frame).C, rtol=1e-10)
    said = capsys.readouterr().out
    assert "xarray" not in said                    # a summary line: the constants, not the repr
    with xr.open_dataset(nc) as ds:
        assert f"E1 {float(ds.E1):.4g}" in said and "largest relative residual" in said
    assert main(["plot", str(nc), "--out", str(tmp_path / "p.png")]) == 0
    assert (tmp_path / "p.png").stat().st_size > 5_000


def test_malformed_cell_file_names_key(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text('[cell]\nname = "x"\ngenerator = "square"\n[parameters]\na = -1.0\n'
                   '[yarns.s]\nsection = "circle"\nradius = 0.1\nE = 1.0\nnu = 0.3\nsource = "t"\n')
    p = subprocess.run([sys.executable, "-m", "homtex.app.cli", "homogenize", str(bad)],
                       capture_output=True, text=True)
    assert p.returncode == 2 and "Traceback" not in p.stderr
    assert "bad.toml" in p.stderr and "[parameters]" in p.stderr and "'a'" in p.stderr


def _linear_curve(path, modulus=100.0, end=0.5):
    """A stored compression law (what `homtex compress` writes): stress = modulus x strain, kPa."""
    from homtex.output.io import write_netcdf

    e = np.linspace(0.0, end, 11)
    return write_netcdf(xr.Dataset({"stress": ("strain", modulus * e, {"units": "kPa", "long_name": "stress"})},
                                   coords={"strain": ("strain", e, {"units": "1", "long_name": "strain"})},
                                   attrs={"thickness_mm": 20.0, "status": "ok"}), path)


def test_stage_commands_write_netcdf_and_png_with_the_physics_of_the_api(tmp_path, capsys):
    """cell, compress, seam, macro and study from the shell: each writes its files, named after
    the cell file, and what is in them is what the API gives (closed forms where there are any)."""
    import homtex

    spacer = "cells/spacer_20mm.toml"
    assert main(["cell", spacer, "--out", str(tmp_path / "cell")]) == 0
    assert (tmp_path / "cell" / "spacer_20mm_cell.png").stat().st_size > 10_000
    assert "thickness: 20.0" in (tmp_path / "cell" / "spacer_20mm_cell.txt").read_text()
    meshio = pytest.importorskip("meshio")
    mesh = meshio.read(tmp_path / "cell" / "spacer_20mm_cell.vtu")
    assert sum(len(c.data) for c in mesh.cells) == homtex.load_cell(spacer).frame.n_elements

    capsys.readouterr()
    assert main(["compress", spacer, "--strain", "0.1", "--steps", "5", "--out", str(tmp_path / "c")]) == 0
    said = capsys.readouterr().out
    stored = tmp_path / "c" / "spacer_20mm_compression.nc"
    with xr.open_dataset(stored) as ds:
        api = homtex.compress(homtex.load_cell(spacer), strain=0.1, steps=5)
        np.testing.assert_allclose(ds.stress.values, api.stress.values, rtol=1e-8)
        # a summary line, not the Dataset's repr: the last stress and the force on 121 cm^2 it means
        assert "xarray" not in said and f"{ds.stress.values[-1]:.4g}" in said
        assert f"{12.1 * ds.stress.values[-1]:.4g} N on a 121 cm^2 plate at 10 %" in said
        assert ds.attrs["geometry"] == api.attrs["geometry"] == "nonlinear"   # one default: the engine
        s, e = ds.stress.values, ds.strain.values
    assert (tmp_path / "c" / "spacer_20mm_compression.png").exists()
    # the macro layer on that stored law, no seams: every column under the 121 cm^2 plate is engaged
    # from the start, so F(w) = 12100 mm^2 x stress(w / 20 mm)
    assert main(["macro", spacer, "--curve", str(stored), "--out", str(tmp_path / "m0")]) == 0
    with xr.open_dataset(tmp_path / "m0" / "spacer_20mm_macro_noseam.nc") as ds:
        w, F = ds.plate_displacement.values, ds.force.values
        np.testing.assert_allclose(F, 12.1 * np.interp(w / 20.0, np.r_[0.0, e], np.r_[0.0, s]), rtol=1e-6)
        assert w[-1] == pytest.approx(2.0)    # the stored curve ends at 10 %

    assert main(["seam", spacer, "--distance", "24", "--method", "foundation", "--out", str(tmp_path / "s")]) == 0
    with xr.open_dataset(tmp_path / "s" / "spacer_20mm_seam_24mm_foundation.nc") as ds:
        assert float(ds.cushion_height) == pytest.approx(14.33, abs=0.01)   # the calibration point
    assert (tmp_path / "s" / "spacer_20mm_seam_24mm_foundation.png").exists()

    law = _linear_curve(tmp_path / "law.nc")
    assert main(["macro", spacer, "--distance", "24", "--seam-method", "foundation", "--curve", str(law),
                 "--out", str(tmp_path / "m")]) == 0
    with xr.open_dataset(tmp_path / "m" / "spacer_20mm_macro_24mm.nc") as ds:
        w, F = ds.plate_displacement.values, ds.force.values
        first = 20.0 - float(ds.attrs["cushion_height_max_mm"])   # the punch meets the crests here
        assert np.all(F[w < first - 1e-9] == 0.0) and np.all(F[w > first + 0.1] > 0.0)
        assert np.all(np.diff(F) >= 0.0)
    assert (tmp_path / "m" / "spacer_20mm_macro_24mm.png").exists()

    capsys.readouterr()
    assert main(["study", "studies/configs/square_stiffness.toml", "--out", str(tmp_path / "st")]) == 0
    said = capsys.readouterr().out
    with xr.open_dataset(tmp_path / "st" / "result.nc") as ds:
        assert "xarray" not in said
        assert f"{ds['status'].size} of {ds['status'].size} points ok" in said
        E = ds["yarns.strut.E"].values[:, None]
        r = ds["yarns.strut.radius"].values[None, :]
        a = 1.0                                                  # cells/square.toml pitch, mm
        C11 = ds.C.sel(row="11", col="11").values
        np.testing.assert_allclose(C11, E * np.pi * r**2 / a, rtol=1e-6)   # stretch-dominated
        assert ds.attrs["complete"] and int(ds.attrs["points_failed"]) == 0
    # a grid study is drawn (heat map of a chosen variable), the README's example included
    assert main(["plot", str(tmp_path / "st" / "result.nc"), "--var", "C", "--sel", "row=11", "--sel", "col=11",
                 "--out", str(tmp_path / "st" / "C11.png")]) == 0
    assert main(["plot", str(tmp_path / "st" / "result.nc")]) == 0
    assert (tmp_path / "st" / "result.png").stat().st_size > 10_000


# ------------------------------------------------------------------ user mistakes: a message, never a traceback
def _homtex(*args):
    return subprocess.run([sys.executable, "-m", "homtex.app.cli", *map(str, args)], capture_output=True, text=True)


def test_an_unknown_option_prints_the_subcommands_usage_and_a_suggestion():
    p = _homtex("compress", "square", "--stran", "0.2")
    assert p.returncode == 2 and "Traceback" not in p.stderr
    assert "usage: homtex compress" in p.stderr                 # the subcommand's usage, not the top level's
    assert "did you mean --strain" in p.stderr
    p = _homtex("seam", "spacer_20mm", "--distance", "24", "--method", "yarm")
    assert p.returncode == 2 and "usage: homtex seam" in p.stderr and "did you mean 'yarn'" in p.stderr
    p = _homtex("sam")
    assert p.returncode == 2 and "did you mean 'seam'" in p.stderr


def test_a_wrong_cell_name_lists_the_shipped_cells(capsys):
    assert main(["cell", "spacer_20m"]) == 2
    err = capsys.readouterr().err
    assert "spacer_20m:" in err and "did you mean spacer_20mm" in err
    for name in ("spacer_20mm", "octet", "square", "honeycomb"):
        assert name in err
    assert main(["cell", "cells"]) == 2          # a folder
    assert "is a folder" in capsys.readouterr().err


def test_bad_values_are_usage_errors():
    for args, what in ((("compress", "square", "--strain", "1.5"), "between 0 and 1"),
                       (("compress", "square", "--steps", "0"), ">= 1"),
                       (("compress", "square", "--steps", "two"), "not an integer"),
                       (("seam", "spacer_20mm", "--distance", "-3"), "> 0"),
                       (("seam", "spacer_20mm", "--distance", "nan"), "not a number"),
                       (("macro", "spacer_20mm", "--seed", "-1"), ">= 0")):
        p = _homtex(*args)
        assert p.returncode == 2 and "Traceback" not in p.stderr and what in p.stderr, (args, p.stderr)
        assert f"usage: homtex {args[0]}" in p.stderr


def _read_only_folder(tmp_path):
    """A folder this process cannot write to (a 0500 folder; for root, whom permissions do not stop, /sys)."""
    from homtex.app.paths import writable

    ro = tmp_path / "ro"
    ro.mkdir(exist_ok=True)
    ro.chmod(0o500)
    if not writable(ro):
        return ro
    if Path("/sys").is_dir() and not writable(Path("/sys")):
        return Path("/sys")
    pytest.skip("no read-only folder for this user here")


def test_out_that_is_a_file_or_not_writable_fails_before_computing(tmp_path, capsys, monkeypatch):
    import homtex.app.commands as commands

    def boom(*a, **k):
        raise AssertionError("computed before checking --out")

    monkeypatch.setattr(commands, "seam_profile", boom)
    f = tmp_path / "file.txt"
    f.write_text("x")
    for out, what in ((f, "is a file"), (f / "sub", "is a file"), (_read_only_folder(tmp_path), "not writable"),
                      (_read_only_folder(tmp_path) / "new", "cannot create")):
        assert main(["seam", "spacer_20mm", "--distance", "24", "--out", str(out)]) == 2, out
        err = capsys.readouterr().err
        assert f"--out {out}" in err and what in err, err


def test_plot_of_a_non_netcdf_file_or_to_an_unknown_extension_is_a_message(tmp_path, capsys):
    txt = tmp_path / "notes.txt"
    txt.write_text("not netCDF\n")
    assert main(["plot", str(txt)]) == 2
    assert "not a netCDF file" in capsys.readouterr().err
    nc = _linear_curve(tmp_path / "law.nc")
    assert main(["plot", str(nc), "--out", str(tmp_path / "chart.xyz")]) == 2
    err = capsys.readouterr().err
    assert "unknown image extension .xyz" in err and ".png" in err
    assert main(["plot", str(nc), "--out", str(tmp_path)]) == 2          # a folder
    assert main(["plot", str(tmp_path)]) == 2
    assert main(["plot", str(tmp_path / "missing.nc")]) == 2
    assert main(["plot", str(nc), "--out", str(tmp_path / "chart.svg")]) == 0
    assert (tmp_path / "chart.svg").stat().st_size > 5_000


def test_a_cell_name_never_becomes_a_path(tmp_path):
    """name = "../outside/escaped" or an absolute name: the files go into --out, named after the cell FILE"""
    import os

    square = Path("cells/square.toml").read_text()
    outside = tmp_path / "abs_target" / "escaped"
    for i, name in enumerate(("../outside/escaped", str(outside), "..", "a/../../b")):
        cell = tmp_path / "cells" / f"evil{i}.toml"
        cell.parent.mkdir(exist_ok=True)
        cell.write_text(square.replace('name = "square"', f"name = {name!r}".replace("'", '"')))
        out = tmp_path / "out" / "here"
        assert main(["cell", str(cell), "--out", str(out)]) == 0
        assert main(["homogenize", str(cell), "--out", str(out)]) == 0
        assert {p.name for p in out.glob(f"evil{i}_*")} >= {f"evil{i}_cell.png", f"evil{i}_cell.txt",
                                                            f"evil{i}_homogenized.nc", f"evil{i}_homogenized.png"}
    written = {str(Path(r) / f) for r, _, fs in os.walk(tmp_path) for f in fs}
    assert all(w.startswith(str(tmp_path / "out" / "here")) or w.startswith(str(tmp_path / "cells"))
               for w in written), sorted(written)
    assert not (tmp_path / "out" / "outside").exists() and not outside.parent.exists()


def test_safe_stem():
    from homtex.app.paths import safe_stem

    assert safe_stem("spacer_20mm") == "spacer_20mm"
    for bad in ("../outside/escaped", "/etc/passwd", "..", "a\\\\b", "x\0y", "", ".hidden"):
        s = safe_stem(bad)
        assert s and "/" not in s and "\\\\" not in s and not s.startswith(".") and "\0" not in s, (bad, s)


def test_written_files_follow_the_umask(tmp_path):
    import os

    from homtex.output.io import write_netcdf

    ds = xr.Dataset({"a": ("x", np.arange(3.0), {"units": "1", "long_name": "a"})})
    old = os.umask(0o022)
    try:
        for umask, mode in ((0o022, 0o644), (0o077, 0o600), (0o002, 0o664)):
            os.umask(umask)
            p = write_netcdf(ds, tmp_path / f"m{umask:o}.nc")
            assert p.stat().st_mode & 0o777 == mode, (oct(umask), oct(p.stat().st_mode))
    finally:
        os.umask(old)


def test_macro_takes_the_step_count_or_a_stored_curve_and_prints_a_summary(tmp_path, capsys, monkeypatch):
    """`homtex macro` computes the law as macro_curve(cell) does (the engine's curve to 70 %), so the
    command and the API give the same answer; --steps sets its plate steps."""
    import homtex.app.commands as commands

    calls = []

    def fake_law(cell, *, strain, steps):
        calls.append((strain, steps))
        return xr.open_dataset(_linear_curve(tmp_path / f"fake{len(calls)}.nc", modulus=80.0 + steps, end=strain)
                               ).load()

    monkeypatch.setattr(commands, "engine_law", fake_law)
    assert main(["macro", "spacer_20mm", "--out", str(tmp_path / "a")]) == 0
    assert main(["macro", "spacer_20mm", "--steps", "7", "--strain", "0.4", "--out", str(tmp_path / "b")]) == 0
    assert calls == [(0.7, 35), (0.7, 7)]      # macro_curve's default law: 35 plate steps to 70 %
    out = capsys.readouterr().out
    # no seams, stress = k eps: F_max = 12100 mm^2 x k x 0.5 / 1000 = 6.05 k N (k = 115 kPa for 35 steps)
    assert "max force 695.8 N at 10.00 mm (50 %)" in out
    assert "force at 30 % (6.0 mm) 417.4 N" in out and "first contact at" in out
    assert "the large-motion engine to 70 % in 7 plate steps" in out
    with xr.open_dataset(tmp_path / "b" / "spacer_20mm_macro_noseam.nc") as ds:
        assert ds.force.values[-1] == pytest.approx(12.1 * 87.0 * 0.4)
    # a stored curve instead of computing one
    law = _linear_curve(tmp_path / "law.nc", modulus=200.0)
    assert main(["macro", "spacer_20mm", "--curve", str(law), "--out", str(tmp_path / "c")]) == 0
    assert len(calls) == 2 and "max force 1210.0 N" in capsys.readouterr().out
    assert main(["macro", "spacer_20mm", "--curve", str(law), "--steps", "5"]) == 2
    assert "not both" in capsys.readouterr().err
    assert main(["macro", "spacer_20mm", "--curve", str(tmp_path / "c" / "spacer_20mm_macro_noseam.png")]) == 2
    assert "not a compression curve" in capsys.readouterr().err
    # --law cushion: every cushion on the sewn cell's own curve (a stand-in here, no sewing), the API's answer
    import homtex
    import homtex.macro as macro

    cushion = xr.open_dataset(_linear_curve(tmp_path / "cushion.nc", modulus=60.0, end=0.7)).load()
    asked = []
    monkeypatch.setattr(macro, "cushion_law", lambda cell, **kw: asked.append(kw) or cushion)
    assert main(["macro", "spacer_20mm", "--distance", "24", "--seam-method", "foundation", "--curve", str(law),
                 "--law", "cushion", "--strain", "0.4", "--out", str(tmp_path / "d")]) == 0
    api = homtex.macro_curve(homtex.load_cell("spacer_20mm"), seam_distance=24.0, curve=xr.open_dataset(law).load(),
                             strain=0.4,
                             law="cushion", cushion_curve=cushion, profile_options={"method": "foundation"})
    with xr.open_dataset(tmp_path / "d" / "spacer_20mm_macro_24mm.nc") as ds:
        assert ds.attrs["law"] == "cushion" and asked[0]["seam_distance"] == 24.0
        np.testing.assert_allclose(ds.force.values, api.force.values, rtol=1e-12)
        # without height scatter every cushion is the stand-in's: F = 12100 mm^2 x 60 kPa x eps / 1000
        np.testing.assert_allclose(ds.force.values, 12.1 * 60.0 * ds.strain.values, rtol=1e-9)
    assert main(["macro", "spacer_20mm", "--law", "cushion", "--curve", str(law)]) == 2
    assert "--law cushion needs --distance" in capsys.readouterr().err


def test_debug_shows_the_traceback_and_an_internal_error_says_so(tmp_path, capsys, monkeypatch):
    import errno

    import homtex.app.cli as cli
    from homtex.errors import InputError

    with pytest.raises(InputError):
        main(["--debug", "cell", "no_such_cell"])
    with pytest.raises(InputError):
        main(["cell", "no_such_cell", "--debug"])

    def bug(args):
        raise ZeroDivisionError("division by zero")

    def full(args):
        raise OSError(errno.ENOSPC, "No space left on device", "x.nc")

    parser = cli.build_parser()
    parser.commands["cell"].set_defaults(func=bug)
    parser.commands["seam"].set_defaults(func=full)
    monkeypatch.setattr(cli, "build_parser", lambda: parser)
    capsys.readouterr()
    assert main(["cell", "square"]) == 3
    err = capsys.readouterr().err
    assert "internal error" in err and "--debug" in err and "Traceback" not in err
    assert main(["seam", "square", "--distance", "3"]) == 2
    assert "No space left on device: x.nc" in capsys.readouterr().err


def test_every_argument_is_documented_with_its_default():
    from homtex.app.cli import build_parser

    parser = build_parser()
    for name, sp in parser.commands.items():
        if name == "study":          # documented by the study engineer
            continue
        for a in sp._actions:
            if a.dest in ("help", "debug"):
                continue
            assert a.help, (name, a.dest)
            text = a.help % {"default": a.default}
            assert "default" in text or a.required or not a.option_strings, (name, a.dest, text)
            if a.option_strings and a.type is not None and a.dest not in ("seed", "steps", "sel", "workers"):
                assert any(u in text for u in ("mm", "fraction", "%", "dimensionless")), (name, a.dest, text)


def test_heartbeat_reports_a_long_block(caplog):
    import logging
    import time

    from homtex.app.paths import heartbeat

    with caplog.at_level(logging.INFO, logger="homtex"):
        with heartbeat("quick thing", every=0.05, quiet=0.5):
            pass
        with heartbeat("long thing", every=0.05, quiet=0.02):
            time.sleep(0.3)
    msgs = [r.getMessage() for r in caplog.records]
    assert not any("quick thing" in m for m in msgs)
    assert sum("... long thing" in m for m in msgs) >= 3 and any("long thing: done" in m for m in msgs)


def test_compress_with_the_large_motion_engine_and_friction(tmp_path, capsys):
    """``--geometry nonlinear --friction MU`` gives the API's large-motion curve (friction recorded,
    energy balanced) in the default file; friction with the linear model is a usage error, not a
    silent zero."""
    import homtex

    spacer = "cells/spacer_20mm.toml"
    out = tmp_path / "nl"
    assert main(["compress", spacer, "--strain", "0.02", "--steps", "2", "--geometry", "nonlinear",
                 "--friction", "0.2", "--out", str(out)]) == 0
    with xr.open_dataset(out / "spacer_20mm_compression.nc") as ds:
        api = homtex.compress(homtex.load_cell(spacer), strain=0.02, steps=2, geometry="nonlinear",
                              contact=homtex.Contact(friction=0.2))
        np.testing.assert_allclose(ds.stress.values, api.stress.values, rtol=1e-8)
        assert ds.attrs["geometry"] == "nonlinear" and ds.attrs["friction_max"] == 0.2
        assert float(ds.friction_energy[-1]) > 0 and abs(float(ds.energy_balance[-1])) < 0.01
    assert (out / "spacer_20mm_compression.png").exists()
    assert main(["compress", spacer, "--geometry", "linear", "--friction", "0.2", "--out", str(tmp_path / "lin")]) == 2
    assert "--geometry nonlinear" in capsys.readouterr().err
    assert not (tmp_path / "lin").exists() or not list((tmp_path / "lin").iterdir())
    # the linear model by name, in its own file, as compress(geometry="linear")
    assert main(["compress", spacer, "--strain", "0.001", "--steps", "1", "--geometry", "linear",
                 "--out", str(tmp_path / "lin")]) == 0
    with xr.open_dataset(tmp_path / "lin" / "spacer_20mm_compression_linear.nc") as ds:
        api = homtex.compress(homtex.load_cell(spacer), strain=0.001, steps=1, geometry="linear")
        np.testing.assert_allclose(ds.stress.values, api.stress.values, rtol=1e-8)
        assert ds.attrs["geometry"] == "linear"


# ------------------------------------------------------------------ interrupts, empty --out, status
def test_the_command_imports_its_heavy_modules_inside_main():
    """Ctrl-C while numpy, numba, scipy, xarray load printed a traceback: the command's module
    imports none of them, so the interrupt reaches main()'s handler."""
    code = ("import sys, homtex.app.cli; "
            "print(sorted(m for m in ('numpy', 'numba', 'scipy', 'xarray') if m in sys.modules))")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=Path(__file__).parents[1])
    assert p.returncode == 0 and p.stdout.strip() == "[]", p.stdout + p.stderr


def test_an_interrupt_while_the_modules_load_is_one_line(capsys, monkeypatch):
    import importlib.abc

    class Interrupt(importlib.abc.MetaPathFinder):
        def find_spec(self, name, path=None, target=None):
            if name == "homtex.app.commands":
                raise KeyboardInterrupt
            return None

    monkeypatch.delitem(sys.modules, "homtex.app.commands", raising=False)
    monkeypatch.setattr(sys, "meta_path", [Interrupt(), *sys.meta_path])
    assert main(["cell", "square"]) == 130
    err = capsys.readouterr().err
    assert err == "homtex cell: interrupted\n"


def test_an_empty_out_is_a_usage_error(tmp_path, capsys, monkeypatch):
    """``--out ""`` fell back to the default folder and exited 0."""
    monkeypatch.chdir(tmp_path)
    for args in (["cell", "square"], ["compress", "spacer_20mm"], ["plot", "x.nc"], ["study", "s.toml"]):
        assert main([*args, "--out", ""]) == 2, args
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "--out ''" in err and "empty" in err, err
    assert list(tmp_path.iterdir()) == []        # nothing written


def _fake_compress(status, detail):
    """compress() that computes a short real curve and marks it ``status``."""
    import homtex
    from homtex.model.results import set_status

    def fake(cell, **kw):
        ds = homtex.compress(cell, strain=0.04, steps=2)
        return set_status(ds, status, detail)
    return fake


@pytest.mark.parametrize("status, code", [("failed", 1), ("flagged", 0), ("ok", 0)])
def test_a_failed_curve_exits_non_zero_and_keeps_its_files(tmp_path, capsys, monkeypatch, status, code):
    """``homtex compress`` exited 0 for a curve whose status is "failed": now 1, with the reason on
    stderr and the files written; "flagged" prints a warning line and exits 0."""
    import homtex.app.stages as stages

    detail = "failed at step 17 (strain 0.64): a step too large" if status != "ok" else ""
    monkeypatch.setattr(stages, "compress", _fake_compress(status, detail))
    out = tmp_path / status
    if code:
        with pytest.raises(SystemExit) as info:
            main(["compress", "spacer_20mm", "--out", str(out)])
        assert info.value.code == code
    else:
        assert main(["compress", "spacer_20mm", "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert (out / "spacer_20mm_compression.nc").is_file() and (out / "spacer_20mm_compression.png").is_file()
    if status == "failed":
        assert err.strip() == f"homtex compress: failed: {detail} (what was computed before it is written)"
    elif status == "flagged":
        assert err.strip() == f"homtex compress: warning: the result is flagged: {detail}"
    else:
        assert "failed" not in err and "warning" not in err


# ------------------------------------------------------------------ homtex tensile (weft knits)
def _coarse_jersey(tmp_path) -> Path:
    """The E-glass jersey with 0.65 mm elements (11 per loop), relaxed and pulled frictionless in
    well under a second; its file says friction 0.3 (the command's --friction 0 must win)."""
    src = Path(__file__).resolve().parents[1] / "cells" / "jersey_eglass.toml"
    text = src.read_text()
    assert "element_length = 0.2" in text and "friction = 0.0" in text
    p = tmp_path / "jersey_coarse.toml"
    p.write_text(text.replace("element_length = 0.2", "element_length = 0.65").replace("friction = 0.0",
                                                                                       "friction = 0.3"))
    return p


def test_tensile_command_gives_the_api_numbers_and_writes_them_with_units(tmp_path, capsys):
    """``homtex tensile`` relaxes the cell and pulls it through homtex.relax / homtex.tensile: the
    same numbers as ``homtex.tensile(cell, ...)`` with the same options (--friction over the cell
    file's), in ``<stem>_tensile_<direction>.nc`` with units, a force-per-width chart and the
    energy split."""
    import homtex
    from homtex.output.charts_data import dataset_kind

    cell = _coarse_jersey(tmp_path)
    out = tmp_path / "t"
    assert main(["tensile", str(cell), "--direction", "wale", "--strain", "0.05", "--steps", "1",
                 "--friction", "0", "--out", str(out)]) == 0
    said = capsys.readouterr().out
    assert "N/mm at 0 / 5 %" in said and "status ok" in said and "relax " in said
    for name in ("jersey_coarse_tensile_wale.nc", "jersey_coarse_tensile_wale.png",
                 "jersey_coarse_tensile_wale_energy.png"):
        assert f"wrote {out / name}" in said and (out / name).stat().st_size > 1000, name
    api = homtex.tensile(homtex.load_cell(cell), strain=0.05, direction="wale", steps=1, friction=0.0)
    with xr.open_dataset(out / "jersey_coarse_tensile_wale.nc") as ds:
        assert dataset_kind(ds) == "knit_tensile" and ds.attrs["direction"] == "wale"
        assert ds.attrs["friction"] == 0.0 and ds.attrs["steps"] == 1 and ds.attrs["status"] == "ok"
        assert ds.attrs["relaxed_wale_spacing_mm"] == pytest.approx(ds.attrs["initial_width_mm"])
        for v in ("force", "force_per_width", "width", "extension", "axial", "torsion", "bending_y", "bending_z",
                  "shear", "contact_energy", "friction_energy", "external_work", "energy_balance",
                  "max_filament_stress"):
            np.testing.assert_allclose(ds[v].values, api[v].values, rtol=1e-10, atol=1e-15, err_msg=v)
            assert ds[v].attrs["units"] == api[v].attrs["units"], v
        assert ds.force.attrs["units"] == "N" and ds.force_per_width.attrs["units"] == "N/mm"
        assert ds.max_filament_stress.attrs["units"] == "MPa" and ds.strain.attrs["units"] == "1"
        # the physics it claims: the relaxation's take-down (0.06 N per 5 needles, one needle) at the
        # start, force per width over the relaxed width, lateral contraction, the ledger closed
        f = ds.force.values
        assert f[0] == pytest.approx(0.06 / 5) and f[1] > f[0]
        assert ds.force_per_width.values == pytest.approx(f / ds.attrs["initial_width_mm"])
        assert float(ds.width[-1]) < float(ds.width[0])
        assert float(ds.external_work[-1]) > 0 and abs(float(ds.energy_balance[-1])) < 0.01


def test_tensile_bad_input_is_one_line_naming_the_culprit(tmp_path, capsys):
    out = str(tmp_path / "bad")
    assert main(["tensile", "square", "--direction", "wale", "--strain", "0.1", "--out", out]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("homtex tensile: error: square: not a weft-knit cell")
    assert "rib_1x1_eglass" in err and "Traceback" not in err
    assert not list(Path(out).iterdir())                        # nothing written
    for args, what in ((["--direction", "diagonal", "--strain", "0.1"], "--direction: invalid choice: 'diagonal'"),
                       (["--direction", "course", "--strain", "0"], "--strain: must be a fraction > 0"),
                       (["--direction", "course", "--strain", "-0.2"], "--strain: must be a fraction > 0"),
                       (["--strain", "0.1"], "required: --direction")):
        assert main(["tensile", "jersey_eglass", *args, "--out", out]) == 2, args
        err = capsys.readouterr().err
        assert what in err and "usage: homtex tensile" in err and "Traceback" not in err, (args, err)
