"""Studies that fail loudly (issue 16): failures counted and retried, point files verified,
output folders and schedulers checked, tasks only from the registry, units kept."""

import copy
import errno
import json
import logging
import os
import re
import socket
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

import homtex.study.runner as runner
from homtex.app.cli import main
from homtex.errors import InputError
from homtex.output.datasets import check_meta
from homtex.output.io import read_netcdf, write_netcdf
from homtex.study import TASKS, StudyError, analytic_task, guess_unit, load_study, register_task, run_study

try:
    import tomllib
except ModuleNotFoundError:  # pragma: no cover - python 3.10
    import tomli as tomllib

ROOT = Path(__file__).resolve().parents[1]

GRID = """
[study]
name = "analytic_grid"
task = "{task}"
[options]
z = 0.5
fail_above = {fail_above}
[parameters]
x = [0.0, 1.0, 2.0, 3.0]
y = [-1.0, 0.0, 1.0]
"""


def write(tmp_path, text, name="study.toml"):
    p = tmp_path / name
    p.write_text(textwrap.dedent(text))
    return p


def grid(tmp_path, fail_above=2.5, task="analytic", name="study.toml"):
    return write(tmp_path, GRID.format(task=task, fail_above=fail_above), name)


def warnings_of(caplog):
    return [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING]


@pytest.fixture
def flaky(monkeypatch):
    """An in-process task "flaky" (the analytic task) that fails for x > 2.5 while
    HOMTEX_TEST_FLAKY is set; counts its calls in ``flaky.calls``."""
    calls = []

    def task(cell=None, **kw):
        calls.append(kw["x"])
        if kw["x"] > 2.5 and os.environ.get("HOMTEX_TEST_FLAKY"):
            raise RuntimeError(f"flaky failure at x = {kw['x']:g}")
        return analytic_task(cell, **kw)

    monkeypatch.setitem(TASKS, "flaky", None)   # removed again after the test
    register_task("flaky")(task)
    task.calls = calls
    return task


# ------------------------------------------------------------------------------------ failures
def test_all_points_failed_cli_exit_status_and_count(tmp_path):
    """12 of 12 points fail: the command says so on stderr (no traceback), exits 1, and says
    result.nc was written with the failures flagged (it is, with status 1 everywhere)."""
    p = grid(tmp_path, fail_above=-1.0)
    out = tmp_path / "out"
    r = subprocess.run([sys.executable, "-m", "homtex.app.cli", "study", str(p), "--out", str(out), "--workers", "1"],
                       capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert r.returncode == 1, r.stderr
    assert "Traceback" not in r.stderr + r.stdout
    assert "12 of 12 points failed: InputError: analytic task: x = 0 exceeds fail_above = -1" in r.stderr
    assert "first failed point: x = 0, y = -1" in r.stderr
    assert "12 failed points are NaN" in r.stdout and str(out / "result.nc") in r.stdout
    ds = read_netcdf(out / "result.nc")
    assert (ds.status.values == 1).all() and ds.attrs["points_failed"] == 12


def test_failed_points_counted_logged_and_in_attrs(tmp_path, caplog):
    p = grid(tmp_path)
    with caplog.at_level(logging.WARNING, logger="homtex"):
        ds = run_study(p, tmp_path / "out", workers=1, progress=False)
    assert (ds.attrs["points_ok"], ds.attrs["points_failed"], ds.attrs["points_not_run"]) == (9, 3, 0)
    assert any(m.endswith("3 of 12 points failed: InputError: analytic task: x = 3 exceeds fail_above = 2.5 "
                          "(first failed point: x = 3, y = -1)") for m in warnings_of(caplog))
    # a clean study logs no warning at all (no summary, no point file reported)
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="homtex"):
        run_study(grid(tmp_path, fail_above=9.0, name="ok.toml"), tmp_path / "ok", workers=1, progress=False)
        run_study(grid(tmp_path, fail_above=9.0, name="ok.toml"), tmp_path / "ok", workers=1, progress=False)
    assert warnings_of(caplog) == []


def test_cli_exit_status_1_and_retry_on_rerun(tmp_path, monkeypatch, capsys, flaky):
    p = grid(tmp_path, task="flaky", fail_above=9.0)
    out = str(tmp_path / "out")
    monkeypatch.setenv("HOMTEX_TEST_FLAKY", "1")
    with pytest.raises(SystemExit) as exc:
        main(["study", p.as_posix(), "--out", out, "--workers", "1"])
    assert exc.value.code == 1
    err = capsys.readouterr().err
    assert "3 of 12 points failed: RuntimeError: flaky failure at x = 3" in err and "retry" in err
    monkeypatch.delenv("HOMTEX_TEST_FLAKY")
    with pytest.raises(SystemExit) as exc:   # --keep-failed: the recorded failures stay
        main(["study", p.as_posix(), "--out", out, "--workers", "1", "--keep-failed"])
    assert exc.value.code == 1 and len(flaky.calls) == 12
    assert read_netcdf(Path(out) / "result.nc").attrs["points_failed"] == 3
    assert main(["study", p.as_posix(), "--out", out, "--workers", "1"]) == 0
    assert read_netcdf(Path(out) / "result.nc").attrs["points_failed"] == 0


def test_resume_retries_failed_points_unless_kept(tmp_path, monkeypatch, flaky):
    p = grid(tmp_path, task="flaky", fail_above=9.0)
    monkeypatch.setenv("HOMTEX_TEST_FLAKY", "1")
    first = run_study(p, tmp_path / "out", workers=1, progress=False)
    assert first.attrs["points_failed"] == 3 and len(flaky.calls) == 12
    monkeypatch.delenv("HOMTEX_TEST_FLAKY")
    kept = run_study(p, tmp_path / "out", workers=1, progress=False, keep_failed=True)
    xr.testing.assert_identical(kept, first)
    assert len(flaky.calls) == 12, "keep_failed runs nothing"
    with pytest.warns(DeprecationWarning, match="keep_failed"):
        old = run_study(p, tmp_path / "out", workers=1, progress=False, retry_failed=False)
    xr.testing.assert_identical(old, first)
    retried = run_study(p, tmp_path / "out", workers=1, progress=False)
    assert len(flaky.calls) == 15 and sorted(flaky.calls[12:]) == [3.0, 3.0, 3.0], "only the failed points run again"
    full = run_study(p, tmp_path / "full", workers=1, progress=False)
    xr.testing.assert_identical(retried, full)
    assert (retried.status.values == 0).all()
    with pytest.raises(InputError, match="contradict"), pytest.warns(DeprecationWarning):
        run_study(p, tmp_path / "out", workers=1, progress=False, retry_failed=True, keep_failed=True)


# ------------------------------------------------------------------------------------ point files
def test_truncated_point_file_is_reported_and_rerun(tmp_path, caplog):
    p = grid(tmp_path)
    full = run_study(p, tmp_path / "out", workers=1, progress=False)
    f = tmp_path / "out" / "points" / "00004.nc"
    data = f.read_bytes()
    f.write_bytes(data[: len(data) // 2])
    with caplog.at_level(logging.WARNING, logger="homtex"):
        again = run_study(p, tmp_path / "out", workers=1, progress=False)
    msgs = [m for m in warnings_of(caplog) if str(f) in m]
    assert len(msgs) == 1 and "cannot be read" in msgs[0] and "runs again" in msgs[0]
    assert (tmp_path / "out" / "points" / "00004.nc.bad").read_bytes() == data[: len(data) // 2]
    xr.testing.assert_identical(again, full)


def test_altered_point_file_is_reported_and_rerun(tmp_path, caplog):
    """A point file whose numbers were changed but still parses (attributes, key and checksum
    copied along) is detected by its checksum and not trusted; so is one without a checksum."""
    p = grid(tmp_path)
    full = run_study(p, tmp_path / "out", workers=1, progress=False)
    pts = tmp_path / "out" / "points"
    changed = read_netcdf(pts / "00004.nc")
    changed["value"] = changed["value"] + 1e-9
    changed.to_netcdf(pts / "00004.nc", engine="netcdf4")
    stripped = read_netcdf(pts / "00007.nc")
    del stripped.attrs["point_sha256"]
    stripped.to_netcdf(pts / "00007.nc", engine="netcdf4")
    with caplog.at_level(logging.WARNING, logger="homtex"):
        again = run_study(p, tmp_path / "out", workers=1, progress=False)
    msgs = warnings_of(caplog)
    assert any(str(pts / "00004.nc") in m and "does not match its checksum" in m for m in msgs)
    assert any(str(pts / "00007.nc") in m and "has no checksum" in m for m in msgs)
    assert (pts / "00004.nc.bad").exists() and (pts / "00007.nc.bad").exists()
    xr.testing.assert_identical(again, full)


def test_point_checksum_survives_netcdf_round_trip(tmp_path):
    """Strings, booleans, NaN payloads, ints and floats hash the same before and after a write."""
    ds = xr.Dataset({"f": ("n", np.array([1.0, -0.0, np.nan, -np.nan, np.inf])),
                     "i8": ((), np.int8(1)), "i": ("n", np.arange(5)), "flag": ("n", np.array([1, 0, 1, 1, 0], bool)),
                     "s": ((), "ünïcode error\nline 2"),
                     "labels": ("n", np.array(["11", "22", "12", "a", ""], object))},
                    coords={"n": ("n", np.arange(5.0))})
    write_netcdf(ds, tmp_path / "a.nc")
    back = read_netcdf(tmp_path / "a.nc")
    assert runner.point_checksum(back) == runner.point_checksum(ds)
    back["f"] = back["f"].copy(data=np.array([1.0, 0.0, np.nan, np.nan, np.inf]))   # -0.0 -> 0.0
    assert runner.point_checksum(back) != runner.point_checksum(ds)


# ------------------------------------------------------------------------------------ output folder
def test_out_dir_that_is_a_file(tmp_path, capsys):
    p = grid(tmp_path)
    f = tmp_path / "result_file"
    f.write_text("not a folder")
    with pytest.raises(StudyError, match=rf"output folder {f} is a file, not a folder"):
        run_study(p, f, workers=1, progress=False)
    assert main(["study", str(p), "--out", str(f), "--workers", "1"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "is a file" in err and "Traceback" not in err
    # a folder given as the study file
    assert main(["study", str(tmp_path), "--out", str(tmp_path / "o"), "--workers", "1"]) == 2
    assert "is a folder, not a study file" in capsys.readouterr().err


def _can_write_read_only(folder: Path) -> bool:
    """True where a chmod 0o555 folder can still be written (root)."""
    probe = folder / "probe"
    probe.mkdir()
    os.chmod(probe, 0o555)
    try:
        (probe / "x").write_text("x")
        return True
    except OSError:
        return False
    finally:
        os.chmod(probe, 0o755)


def test_read_only_out_dir(tmp_path, capsys):
    if _can_write_read_only(tmp_path):
        pytest.skip("running as root: chmod does not stop writes (the simulated test below covers the message)")
    p = grid(tmp_path)
    out = tmp_path / "out"
    run_study(p, out, workers=1, progress=False, max_points=4)
    for d in (out / "points", out):
        os.chmod(d, 0o555)
    try:
        with pytest.raises(StudyError, match=rf"output folder {out} is not writable"):
            run_study(p, out, workers=1, progress=False)
        assert main(["study", str(p), "--out", str(out), "--workers", "1"]) == 2
        assert "not writable" in capsys.readouterr().err
        with pytest.raises(StudyError, match="not writable"):  # a new folder below a read-only one
            run_study(p, out / "sub", workers=1, progress=False)
    finally:
        for d in (out, out / "points"):
            os.chmod(d, 0o755)
    ds = run_study(p, out, workers=1, progress=False)
    xr.testing.assert_identical(ds, run_study(p, tmp_path / "full", workers=1, progress=False))


def test_read_only_out_dir_simulated(tmp_path, monkeypatch, capsys):
    """The same as a read-only folder, where chmod cannot make one (root): the write probe
    is refused with EACCES (EROFS: a read-only file system)."""
    p = grid(tmp_path)
    real_open = os.open

    def refuse(path, *a, **kw):
        if ".write-probe-" in str(path):
            raise PermissionError(errno.EACCES, "Permission denied", str(path))
        return real_open(path, *a, **kw)

    monkeypatch.setattr(os, "open", refuse)
    with pytest.raises(StudyError, match=rf"output folder {tmp_path / 'out'} is not writable \(Permission denied\)"):
        run_study(p, tmp_path / "out", workers=1, progress=False)
    assert main(["study", str(p), "--out", str(tmp_path / "out"), "--workers", "1"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "not writable" in err


def test_full_disk_is_a_clear_error_and_resume_completes(tmp_path, monkeypatch, capsys):
    p = grid(tmp_path)
    out = tmp_path / "out"
    real = runner.write_netcdf
    written = []

    def fill_up(ds, path):
        if len(written) >= 5:
            raise OSError(errno.ENOSPC, "No space left on device", str(path))
        written.append(path)
        return real(ds, path)

    monkeypatch.setattr(runner, "write_netcdf", fill_up)
    with pytest.raises(StudyError, match=rf"disk holding the output folder {out} is full.*5 of 12 points are "
                                         r"finished and kept .*run the study again to resume"):
        run_study(p, out, workers=1, progress=False)
    assert main(["study", str(p), "--out", str(out), "--workers", "1"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "is full" in err and "Traceback" not in err
    # the result file alone does not fit: still a clear error, every point kept
    monkeypatch.setattr(runner, "write_netcdf",
                        lambda ds, path: fill_up(ds, path) if Path(path).name == "result.nc" else real(ds, path))
    with pytest.raises(StudyError, match=r"is full.*all 12 points are finished.*write result.nc"):
        run_study(p, out, workers=1, progress=False)
    monkeypatch.setattr(runner, "write_netcdf", real)
    assert len(list((out / "points").glob("*.nc"))) == 12 and not list((out / "points").glob("*.bad"))
    resumed = run_study(p, out, workers=1, progress=False)
    xr.testing.assert_identical(resumed, run_study(p, tmp_path / "full", workers=1, progress=False))


# ------------------------------------------------------------------------------------ scheduler
def test_unreachable_scheduler_fails_fast(tmp_path, capsys):
    pytest.importorskip("distributed")
    with socket.socket() as s:  # a free local port: nothing listens there
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    address = f"tcp://127.0.0.1:{port}"
    p = grid(tmp_path)
    t0 = time.perf_counter()
    with pytest.raises(StudyError, match=rf"cannot reach the dask scheduler at '{address}' \(ConnectionRefused"):
        run_study(p, tmp_path / "out", scheduler=address, connect_timeout=1.0, progress=False)
    assert time.perf_counter() - t0 < 3
    t0 = time.perf_counter()
    assert main(["study", str(p), "--out", str(tmp_path / "out"), "--scheduler", address,
                 "--connect-timeout", "1"]) == 2
    assert time.perf_counter() - t0 < 3
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and address in err and "Traceback" not in err
    # something listens but never answers (a dask Client would wait for ever): the connect timeout
    with socket.socket() as silent:
        silent.bind(("127.0.0.1", 0))
        silent.listen(8)
        address = f"tcp://127.0.0.1:{silent.getsockname()[1]}"
        t0 = time.perf_counter()
        with pytest.raises(StudyError, match=rf"at '{address}' \(TimeoutError: no answer from a dask scheduler "
                                             r"within 1 s"):
            run_study(p, tmp_path / "out", scheduler=address, connect_timeout=1.0, progress=False)
        assert time.perf_counter() - t0 < 4
    with pytest.raises(InputError, match="connect_timeout"):
        run_study(p, tmp_path / "out", scheduler=address, connect_timeout=0, progress=False)


# ------------------------------------------------------------------------------------ task registry
@pytest.mark.parametrize("task", ["json:dumps", "os:system", "homtex.study.tasks:analytic_task", "os.system"])
def test_import_path_task_is_rejected(tmp_path, capsys, task):
    p = grid(tmp_path, task=task)
    with pytest.raises(InputError, match=r"\[study\] key 'task'.*not code to import.*'analytic'.*homtex.tasks"):
        load_study(p)
    assert main(["study", str(p), "--out", str(tmp_path / "out"), "--workers", "1"]) == 2
    assert not (tmp_path / "out").exists()
    with pytest.raises(InputError, match=r"unknown task 'nope'; registered tasks: \['analytic', 'compress'"):
        load_study(grid(tmp_path, task="nope"))


def test_entry_point_task_and_in_process_tasks(tmp_path, monkeypatch, caplog, flaky):
    """A task declared by an installed package (entry point) runs; one registered in this
    process runs with workers=1 (the default falls back to it, with a warning) and is refused
    with workers > 1 or a scheduler."""
    site = tmp_path / "site"
    site.mkdir()
    (site / "ep_tasks_robust.py").write_text("from homtex.study import analytic_task as task\n")
    info = site / "ep_tasks_robust-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: ep-tasks-robust\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text("[homtex.tasks]\nmy_analytic = ep_tasks_robust:task\n")
    monkeypatch.syspath_prepend(str(site))
    from homtex.study import task_names

    assert "my_analytic" in task_names()
    ep = run_study(grid(tmp_path, task="my_analytic", name="ep.toml"), tmp_path / "ep", workers=1, progress=False)
    ref = run_study(grid(tmp_path), tmp_path / "ref", workers=1, progress=False)
    xr.testing.assert_identical(ep.drop_attrs(), ref.drop_attrs())

    p = grid(tmp_path, task="flaky", name="flaky.toml")
    with pytest.raises(StudyError, match="registered in this process only.*workers=1.*homtex.tasks"):
        run_study(p, tmp_path / "f", workers=2, progress=False)
    with pytest.raises(StudyError, match="registered in this process only"):
        run_study(p, tmp_path / "f", scheduler="tcp://127.0.0.1:1", progress=False)
    with caplog.at_level(logging.WARNING, logger="homtex"):
        ds = run_study(p, tmp_path / "f", progress=False)
    assert any("registered in this process only" in m for m in warnings_of(caplog))
    assert ds.attrs["points_ok"] == 9
    with pytest.raises(InputError, match="built-in"):
        register_task("homogenize")


# ------------------------------------------------------------------------------------ units
def test_parameter_units_guessed():
    want = {"yarns.strut.E": "MPa", "yarns.pile.G": "MPa", "yarns.strut.radius": "mm", "yarns.pile.semi_axes": "mm",
            "parameters.thickness": "mm", "parameters.gap": "mm", "seam_distance": "mm", "stitch_length": "mm",
            "height_scatter": "mm", "plate_force": "N", "stress": "kPa", "contact_pressure": "kPa",
            "prestrain": "1", "parameters.seam.prestrain": "1", "nu": "1", "x": "1", "strain": "1"}
    assert {k: guess_unit(k) for k in want} == want


def _toml(d: dict, prefix: str = "") -> str:
    """A small TOML writer for study tables (strings, numbers, lists, nested tables)."""
    def val(v):
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, str):
            return json.dumps(v)
        if isinstance(v, list):
            return "[" + ", ".join(val(x) for x in v) + "]"
        return repr(v)
    lines = []
    for name, table in d.items():
        lines.append(f"[{prefix}{name}]")
        lines += [f"{json.dumps(k)} = {val(v)}" for k, v in table.items() if not isinstance(v, dict)]
        lines += [_toml({k: v}, f"{prefix}{name}.") for k, v in table.items() if isinstance(v, dict)]
    return "\n".join(lines) + "\n"


def test_shipped_study_files_keep_units(tmp_path):
    """Every study file under studies/ (one point each, or two samples; the seam and macro
    tasks with the fast foundation seam model; macro with a small compression curve and the
    [units] tables dropped so that the guesses are used): complete metadata, the task's units
    on every variable (mm and N stay mm and N) and the parameters' units guessed."""
    e = np.linspace(0.05, 0.5, 10)
    xr.Dataset({"stress": ("strain", 40.0 * e, {"units": "kPa", "long_name": "stress"})},
               coords={"strain": ("strain", e, {"units": "1", "long_name": "strain"})},
               attrs={"thickness_mm": 20.0}).to_netcdf(tmp_path / "curve.nc")
    files = [f for f in sorted(ROOT.glob("studies/**/*.toml")) if "study" in tomllib.loads(f.read_text())]
    assert len(files) >= 4
    for f in files:
        data = tomllib.loads(f.read_text())
        d = copy.deepcopy(data)
        if "cell" in d["study"]:
            d["study"]["cell"] = str((f.parent / d["study"]["cell"]).resolve())
        opts = d.setdefault("options", {})
        if "curve_file" in opts:
            opts["curve_file"] = str(tmp_path / "curve.nc")
        if d["study"]["task"] == "seam":
            opts["method"] = "foundation"
        if d["study"]["task"] == "macro":
            opts["profile_options"] = {"method": "foundation"}
            opts["steps"] = 11
        if "parameters" in d:
            d["parameters"] = {k: v[:1] for k, v in d["parameters"].items()}
        else:
            d["sampling"]["n"] = 2
        units = d.pop("units", {})
        p = tmp_path / f.name
        p.write_text(_toml(d))
        ds = run_study(p, tmp_path / f.stem, workers=1, progress=False)
        assert ds.attrs["points_failed"] == 0, (f.name, summarize_errors(ds))
        assert check_meta(ds) == [], f.name
        point = read_netcdf(sorted((tmp_path / f.stem / "points").glob("*.nc"))[0])
        names = json.loads(ds.attrs["study_parameters"])
        for name in [*point.data_vars, *point.coords]:
            if name in ds.variables and name not in [*names, "status", "error", "check"]:
                assert ds[name].attrs["units"] == point[name].attrs["units"], (f.name, name)
                assert ds[name].attrs["long_name"] == point[name].attrs["long_name"], (f.name, name)
        assert {ds[v].attrs["units"] for v in ds.data_vars} & {"mm", "N", "N/mm"}, f.name
        for k, u in units.items():  # the guesses agree with the units the shipped files give
            assert ds[k].attrs["units"] == u, (f.name, k)


def summarize_errors(ds):
    return sorted(set(map(str, ds.error.values.ravel())))


def test_bad_inputs_named_before_any_point_runs(tmp_path, capsys):
    """The issue's study of 12 points that all failed on a missing input file: now one error
    when the study is loaded, naming the option; [units] of a name that is not a parameter too."""
    p = write(tmp_path, """
    [study]
    name = "macro"
    task = "macro"
    [options]
    curve_file = "no_such_curve.nc"
    [parameters]
    height_scatter = [0.0, 1.0, 2.0]
    seam_distance = [18.0, 24.0, 43.0, 50.0]
    """)
    with pytest.raises(StudyError, match=r"\[options\] key 'curve_file': input file .*no_such_curve.nc' does not"):
        load_study(p)
    assert main(["study", str(p), "--out", str(tmp_path / "out"), "--workers", "1"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no_such_curve.nc" in err
    assert not (tmp_path / "out").exists()
    with pytest.raises(StudyError, match=r"\[units\] key 'z': not a parameter"):
        load_study(write(tmp_path, GRID.format(task="analytic", fail_above=1.0) + '[units]\nz = "mm"\n', "u.toml"))


@pytest.mark.parametrize("code, words", [(errno.EROFS, "not writable (Read-only file system)"),
                                         (errno.EACCES, "not writable (Permission denied)"),
                                         (errno.ENOSPC, "is full")])
def test_a_read_only_folder_on_a_full_disk_is_called_read_only(tmp_path, monkeypatch, capsys, code, words):
    """The write probe refused with EROFS (a read-only mount) on a disk with no space left was
    reported as "full": the error number decides, the free space only when there is none."""
    import shutil

    from homtex.output import io

    p = grid(tmp_path)
    real_open = os.open

    def refuse(path, *a, **kw):
        if ".write-probe-" in str(path):
            raise OSError(code, os.strerror(code), str(path))
        return real_open(path, *a, **kw)

    monkeypatch.setattr(os, "open", refuse)
    monkeypatch.setattr(io.shutil, "disk_usage", lambda f: shutil._ntuple_diskusage(100, 100, 0))
    with pytest.raises(StudyError, match=re.escape(words)):
        run_study(p, tmp_path / "out", workers=1, progress=False)
    assert main(["study", str(p), "--out", str(tmp_path / "out"), "--workers", "1"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and words in err and ("full" in err) == (code == errno.ENOSPC)


@pytest.mark.parametrize("code, words", [(errno.EROFS, "a read-only file system"), (errno.EACCES, "permission denied"),
                                         (errno.ENOSPC, "the disk is full")])
def test_an_unwritable_out_folder_names_its_cause(tmp_path, monkeypatch, code, words):
    """The command line's --out check: a read-only folder on a full disk is read-only, not full."""
    import shutil
    import tempfile

    from homtex.app.paths import output_folder
    from homtex.output import io

    def refuse(*a, **kw):
        raise OSError(code, os.strerror(code))

    monkeypatch.setattr(tempfile, "mkstemp", refuse)
    monkeypatch.setattr(io.shutil, "disk_usage", lambda f: shutil._ntuple_diskusage(100, 100, 0))
    with pytest.raises(InputError, match=re.escape(words)) as info:
        output_folder(tmp_path)
    assert ("full" in str(info.value)) == (code == errno.ENOSPC)
