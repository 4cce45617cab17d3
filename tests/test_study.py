"""Parameter studies: resume after a kill, failed points, executors, sampling."""

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from homtex.errors import InputError
from homtex.output.datasets import check_meta
from homtex.output.io import read_netcdf
from homtex.study import TASKS, StudyError, analytic_task, load_study, register_task, run_study

ROOT = Path(__file__).resolve().parents[1]

GRID = """
[study]
name = "analytic_grid"
task = "analytic"
[options]
z = 0.5
fail_above = 2.5
sleep = {sleep}
[parameters]
x = [0.0, 1.0, 2.0, 3.0]
y = [-1.0, 0.0, 1.0]
"""


def write(tmp_path, text, name="study.toml"):
    p = tmp_path / name
    p.write_text(textwrap.dedent(text))
    return p


def test_grid_values_failures_and_metadata(tmp_path):
    p = write(tmp_path, GRID.format(sleep=0.0))
    ds = run_study(p, tmp_path / "out", workers=1, progress=False)
    assert ds["value"].dims == ("x", "y") and ds["curve"].dims == ("x", "y", "t")
    ok = ds.x.values <= 2.5
    X, Y = np.meshgrid(ds.x.values, ds.y.values, indexing="ij")
    exact = np.sin(X) + Y ** 2 + 0.5 * X
    np.testing.assert_allclose(ds["value"].values[ok], exact[ok], rtol=1e-15)
    # the failing points (x = 3) are recorded and masked; the others completed
    assert (ds.status.values[~ok] == 1).all() and (ds.status.values[ok] == 0).all()
    assert all("exceeds fail_above" in e for e in ds.error.values[~ok].ravel())
    assert all(e == "" for e in ds.error.values[ok].ravel())
    assert np.isnan(ds["value"].values[~ok]).all() and np.isfinite(ds["value"].values[ok]).all()
    assert ds.attrs["points_failed"] == 3 and ds.attrs["points_ok"] == 9
    assert check_meta(ds) == []
    assert "homtex_version" in ds.attrs
    on_disk = read_netcdf(tmp_path / "out" / "result.nc")
    xr.testing.assert_identical(on_disk, ds)


def test_budget_stop_and_resume_identical(tmp_path):
    p = write(tmp_path, GRID.format(sleep=0.0))
    full = run_study(p, tmp_path / "full", workers=1, progress=False)
    part = run_study(p, tmp_path / "res", workers=1, progress=False, max_points=5)
    assert part.attrs["complete"] == 0 and (part.status.values == -1).sum() == 7
    assert not (tmp_path / "res" / "result.nc").exists()
    rng = np.random.default_rng(7)
    for k in rng.integers(1, 4, 3):  # several interruptions at random points
        run_study(p, tmp_path / "res", workers=1, progress=False, max_points=int(k))
    resumed = run_study(p, tmp_path / "res", workers=1, progress=False)
    xr.testing.assert_identical(resumed, full)


def test_lost_points_and_stray_temp_files_resume_identical(tmp_path):
    p = write(tmp_path, GRID.format(sleep=0.0))
    full = run_study(p, tmp_path / "out", workers=1, progress=False)
    files = sorted((tmp_path / "out" / "points").glob("*.nc"))
    for i in np.random.default_rng(3).choice(len(files), 5, replace=False):
        files[i].unlink()
    (tmp_path / "out" / "points" / ".00003.nc.abc.tmp").write_bytes(b"half a file")
    again = run_study(p, tmp_path / "out", workers=1, progress=False)
    xr.testing.assert_identical(again, full)
    assert not list((tmp_path / "out" / "points").glob(".*.tmp"))


def test_killed_process_resumes_identical(tmp_path):
    p = write(tmp_path, GRID.format(sleep=0.15))
    out = tmp_path / "killed"
    code = f"from homtex.study import run_study; run_study({str(p)!r}, {str(out)!r}, workers=1, progress=False)"
    proc = subprocess.Popen([sys.executable, "-c", code], cwd=ROOT)
    try:
        deadline = time.time() + 30
        while len(list((out / "points").glob("*.nc"))) < 3 and time.time() < deadline:
            time.sleep(0.02)
        os.kill(proc.pid, signal.SIGKILL)
    finally:
        proc.wait()
    done = len(list((out / "points").glob("*.nc")))
    assert 3 <= done < 12, "the kill should land mid-study"
    resumed = run_study(p, out, workers=1, progress=False)
    full = run_study(p, tmp_path / "full", workers=1, progress=False)
    xr.testing.assert_identical(resumed, full)


def test_process_pool_matches_serial(tmp_path):
    p = write(tmp_path, GRID.format(sleep=0.0))
    serial = run_study(p, tmp_path / "a", workers=1, progress=False)
    pool = run_study(p, tmp_path / "b", workers=2, progress=True)
    xr.testing.assert_identical(serial, pool)


def test_dask_local_cluster(tmp_path):
    distributed = pytest.importorskip("distributed")
    p = write(tmp_path, GRID.format(sleep=0.0))
    serial = run_study(p, tmp_path / "a", workers=1, progress=False)
    # worker processes: HDF5 is not thread-safe, and netCDF files written from worker threads of an
    # in-process cluster are finalised after it shuts down ("IOLoop is closed")
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster, distributed.Client(cluster) as client:
        ds = run_study(p, tmp_path / "b", scheduler=client, progress=False)
        # the address path (a Client made by the runner) resumes the same folder
        (tmp_path / "b" / "points" / "00004.nc").unlink()
        ds2 = run_study(p, tmp_path / "b", scheduler=cluster.scheduler_address, progress=False)
        # a worker's address is not mistaken for the scheduler's
        worker = next(iter(client.scheduler_info()["workers"]))
        with pytest.raises(StudyError, match=r"answers as a dask Worker, not as the scheduler"):
            run_study(p, tmp_path / "c", scheduler=worker, progress=False)
    xr.testing.assert_identical(ds, serial)
    xr.testing.assert_identical(ds2, serial)


SAMPLED = """
[study]
name = "sampled"
task = "analytic"
[sampling]
method = "{method}"
n = {n}
seed = {seed}
[sampling.bounds]
x = [0.0, 2.0]
y = [-1.0, 1.0]
[units]
x = "mm"
"""


@pytest.mark.parametrize("method,n", [("lhs", 10), ("sobol", 16), ("sobol", 12)])
def test_sampling_seeded_and_in_bounds(tmp_path, method, n):
    a = load_study(write(tmp_path, SAMPLED.format(method=method, n=n, seed=4), "a.toml"))
    b = load_study(write(tmp_path, SAMPLED.format(method=method, n=n, seed=4), "b.toml"))
    c = load_study(write(tmp_path, SAMPLED.format(method=method, n=n, seed=5), "c.toml"))
    pa = np.array([[q["x"], q["y"]] for q in a.points])
    pb = np.array([[q["x"], q["y"]] for q in b.points])
    pc = np.array([[q["x"], q["y"]] for q in c.points])
    np.testing.assert_array_equal(pa, pb)
    assert not np.allclose(pa, pc)
    assert pa.shape == (n, 2) and (pa[:, 0] >= 0).all() and (pa[:, 0] <= 2).all()
    assert (pa[:, 1] >= -1).all() and (pa[:, 1] <= 1).all()
    if method == "lhs":  # one sample in each of the n strata of every axis
        for j, (lo, hi) in enumerate([(0, 2), (-1, 1)]):
            strata = np.floor((pa[:, j] - lo) / (hi - lo) * n).astype(int)
            assert sorted(strata) == list(range(n))


def test_sampled_study_dataset(tmp_path):
    p = write(tmp_path, SAMPLED.format(method="lhs", n=8, seed=1))
    ds = run_study(p, tmp_path / "out", workers=1, progress=False)
    assert ds["value"].dims == ("sample",) and ds.x.dims == ("sample",)
    np.testing.assert_allclose(ds["value"].values, np.sin(ds.x.values) + ds.y.values ** 2, rtol=1e-15)
    assert ds.x.attrs["units"] == "mm" and check_meta(ds) == []


def square_study(tmp_path, name, parameters):
    """A homogenize study of the square verification lattice; ``parameters``: TOML lines."""
    head = textwrap.dedent(f"""
        [study]
        name = "{name}"
        cell = "{ROOT / 'cells' / 'square.toml'}"
        task = "homogenize"
        [options]
        solver = "direct"
        [parameters]
        """)
    return write(tmp_path, head + textwrap.dedent(parameters).lstrip("\n"))


def test_homogenize_task_on_square_cell_scales_with_E(tmp_path):
    p = square_study(tmp_path, "square_E", """
    "yarns.strut.E" = [1000.0, 3000.0]
    "yarns.strut.radius" = [0.04, 0.05]
    """)
    ds = run_study(p, tmp_path / "out", workers=1, progress=False)
    assert (ds.status.values == 0).all()
    C = ds["C"]
    # linear elasticity: the effective stiffness is proportional to the yarn modulus
    np.testing.assert_allclose(C.sel({"yarns.strut.E": 3000.0}).values, 3 * C.sel({"yarns.strut.E": 1000.0}).values,
                               rtol=1e-8, atol=1e-12)
    # stretch-dominated square lattice: C11 = E A / a (per unit length, a = 1 mm)
    c11 = C.sel(row=C.row.values[0], col=C.col.values[0])
    r = ds["yarns.strut.radius"].values
    E = ds["yarns.strut.E"].values
    np.testing.assert_allclose(c11.values, E[:, None] * np.pi * r[None, :] ** 2, rtol=1e-6)
    assert ds.attrs["cell.name"] == "square" and check_meta(ds) == []
    # the task's units survive combining (C of a 2-D cell in N/mm, not "1"), and the Voigt
    # labels of the homogenize task are described coordinates
    assert C.attrs["units"] == "N/mm" and ds["C_full"].attrs["units"] == "N/mm"
    assert ds["yarns.strut.E"].attrs["units"] == "MPa" and ds["yarns.strut.radius"].attrs["units"] == "mm"
    for c in ("row", "col", "case", "row_full", "col_full"):
        assert ds[c].attrs["units"] == "1" and "Voigt component" in ds[c].attrs["long_name"], c
    on_disk = read_netcdf(tmp_path / "out" / "result.nc")
    for c in ("row", "col", "case", "row_full", "col_full", "C"):
        assert on_disk[c].attrs == ds[c].attrs


def test_process_pool_after_a_computation_in_the_parent(tmp_path):
    """The usual session: compute something, then run a study on the local pool. Workers forked
    from a process whose numba / BLAS thread pools had run died on their first kernel
    (BrokenProcessPool); they start fresh now and give the serial result."""
    import homtex

    homtex.compress(homtex.load_cell(ROOT / "cells" / "spacer_20mm.toml"), strain=0.02, steps=2)
    p = square_study(tmp_path, "square_pool", """
    "yarns.strut.radius" = [0.04, 0.05]
    """)
    pool = run_study(p, tmp_path / "pool", workers=2, progress=False)
    serial = run_study(p, tmp_path / "serial", workers=1, progress=False)
    assert (pool.status.values == 0).all()
    xr.testing.assert_allclose(pool.C, serial.C, rtol=1e-12)


def test_bad_study_files_named(tmp_path):
    with pytest.raises(StudyError, match=r"\[sampling\] key 'method'"):
        load_study(write(tmp_path, SAMPLED.format(method="grid", n=4, seed=1)))
    with pytest.raises(StudyError, match=r"\[study\] key 'task'.*unknown task 'nope'"):
        load_study(write(tmp_path, '[study]\nname = "a"\ntask = "nope"\n[parameters]\nx = [1.0]\n'))
    with pytest.raises(InputError, match="changes the cell"):
        load_study(write(tmp_path, '[study]\nname = "a"\ntask = "analytic"\n[parameters]\n"yarns.s.E" = [1.0]\n'))
    # an output folder of another study is not mixed in
    p1 = write(tmp_path, GRID.format(sleep=0.0), "g1.toml")
    run_study(p1, tmp_path / "out", workers=1, progress=False, max_points=1)
    p2 = write(tmp_path, GRID.format(sleep=0.0).replace("z = 0.5", "z = 0.7"), "g2.toml")
    with pytest.raises(StudyError, match="different study"):
        run_study(p2, tmp_path / "out", workers=1, progress=False)


def test_macro_study_with_curve_file(tmp_path):
    e = np.linspace(0.05, 0.5, 10)
    xr.Dataset({"stress": ("strain", 40.0 * e)}, coords={"strain": e},
               attrs={"thickness_mm": 20.0}).to_netcdf(tmp_path / "curve.nc")
    p = write(tmp_path, """
    [study]
    name = "macro"
    task = "macro"
    [options]
    curve_file = "curve.nc"
    strain = 0.5
    steps = 51
    [parameters]
    height_scatter = [0.0, 1.0]
    """)
    ds = run_study(p, tmp_path / "out", workers=1, progress=False)
    assert ds.force.dims == ("height_scatter", "step")
    # no seams: the closed form F = 40 kPa * strain * 12100 mm^2, independent of the scatter
    np.testing.assert_allclose(ds.force.values, 40.0 * ds.strain.values * 12100.0 * 1e-3, rtol=1e-12)


def declare_tasks(tmp_path, monkeypatch, module: str, source: str, tasks: dict) -> Path:
    """An installed package, as far as importlib.metadata sees it: ``module`` (``source``) and a
    dist-info whose entry_points.txt declares ``tasks`` {name: "module:function"} in the group
    ``homtex.tasks``; on sys.path here and on PYTHONPATH for worker processes."""
    site = tmp_path / "site"
    site.mkdir(exist_ok=True)
    (site / f"{module}.py").write_text(textwrap.dedent(source))
    info = site / f"{module}-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {module}\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text("[homtex.tasks]\n" + "".join(f"{k} = {v}\n" for k, v in tasks.items()))
    monkeypatch.syspath_prepend(str(site))
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([str(site), str(ROOT), os.environ.get("PYTHONPATH", "")]))
    return site


def test_a_dead_worker_is_a_clear_error_and_finished_points_stay(tmp_path, monkeypatch):
    """A worker killed outside Python (here: os._exit, as the OOM killer would) cannot be
    attributed to a point: the study stops with a StudyError that says how many points are kept,
    and a rerun without the crash resumes to the uninterrupted result. The task is one an
    installed package declares through the ``homtex.tasks`` entry point group: the spawned pool
    workers find it too."""
    declare_tasks(tmp_path, monkeypatch, "crashy_tasks", """
        import os
        from homtex.study import analytic_task

        def task(cell=None, *, x=0.0, y=0.0, **kw):
            if x > 2.5 and os.environ.get("HOMTEX_TEST_CRASH"):
                os._exit(9)
            return analytic_task(cell, x=x, y=y, **kw)
    """, {"crashy": "crashy_tasks:task"})
    monkeypatch.setenv("HOMTEX_TEST_CRASH", "1")
    p = write(tmp_path, GRID.format(sleep=0.0).replace('task = "analytic"', 'task = "crashy"')
              .replace("fail_above = 2.5\n", ""))
    with pytest.raises(StudyError, match=r"worker process died.*points are finished and kept"):
        run_study(p, tmp_path / "out", workers=2, progress=False)
    monkeypatch.delenv("HOMTEX_TEST_CRASH")
    resumed = run_study(p, tmp_path / "out", workers=2, progress=False)
    full = run_study(p, tmp_path / "full", workers=1, progress=False)
    xr.testing.assert_identical(resumed, full)
    assert (full.status.values == 0).all()


def test_a_warning_of_a_point_result_is_kept(tmp_path, monkeypatch):
    """A point whose result carries a warning (attrs "check", e.g. a compression curve whose
    force drops) keeps it in the study's ``check`` variable; the others read ''. (The task is
    registered in this process: it runs with workers=1.)"""
    def warny(cell=None, *, x=0.0, y=0.0, **kw):
        ds = analytic_task(cell, x=x, y=y, **kw)
        if x > 1.5:
            ds.attrs["check"] = f"force drop at x = {x:g}"
        return ds

    monkeypatch.setitem(TASKS, "warny", None)   # undone after the test
    register_task("warny")(warny)
    p = write(tmp_path, GRID.format(sleep=0.0).replace('task = "analytic"', 'task = "warny"')
              .replace("fail_above = 2.5\n", ""))
    ds = run_study(p, tmp_path / "out", workers=1, progress=False)
    assert (ds.status.values == 0).all()
    for x in ds.x.values:
        want = f"force drop at x = {x:g}" if x > 1.5 else ""
        assert set(ds.check.sel(x=x).values.ravel()) == {want}
    assert check_meta(ds) == []


def test_too_many_points_are_refused_before_any_is_made(tmp_path):
    """A 200^4 grid or n = 1e9 samples exhausted the memory while the points were made; both are
    a StudyError naming the table, key and limit, at once."""
    from homtex.study.files import MAX_POINTS

    values = "[" + ", ".join(str(float(i)) for i in range(200)) + "]"
    grid = "[study]\nname = \"big\"\ntask = \"analytic\"\n[parameters]\n" + "".join(
        f"p{i} = {values}\n" for i in range(4))
    t0 = time.perf_counter()
    with pytest.raises(StudyError, match=rf"\[parameters\] key 'p0'.*1\.6e\+09 points.*{MAX_POINTS:,}") as info:
        load_study(write(tmp_path, grid, "grid.toml"))
    assert info.value.file.endswith("grid.toml")
    with pytest.raises(StudyError, match=rf"\[sampling\] key 'n': must be at most {MAX_POINTS:,}"):
        load_study(write(tmp_path, SAMPLED.format(method="lhs", n=10 ** 9, seed=1), "samples.toml"))
    assert time.perf_counter() - t0 < 1.0
    assert load_study(write(tmp_path, grid.replace(values, "[1.0, 2.0]"), "small.toml")).n_points == 16


def test_a_study_path_to_an_endless_file_is_refused(tmp_path):
    if not Path("/dev/zero").exists():
        pytest.skip("no /dev/zero here")
    with pytest.raises(StudyError, match="not a regular file"):
        load_study("/dev/zero")
