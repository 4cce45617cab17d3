"""Running a study: every point an independent job, results written atomically, resumable.

Every point is an independent job ``_run_point(job)`` that writes
``out_dir/points/NNNNN.nc`` atomically (temp file + ``os.replace``), so a killed study
resumes where it stopped: finished point files are skipped. A point whose task raises is
recorded (``status`` = 1, ``error`` = message, its values masked) and the others complete.
Executors: in-process for ``workers=1``, a local process pool by default, dask.distributed
when ``scheduler`` is an address or a ``distributed.Client`` (same job function).

The combined Dataset is always assembled from the point files, so a resumed study gives a
Dataset identical to an uninterrupted one. Per-point wall times stay in the point files'
attributes (``seconds``), not in the combined Dataset.
"""

from __future__ import annotations

import multiprocessing
import os
import time
from concurrent.futures import BrokenExecutor, ProcessPoolExecutor, as_completed
from pathlib import Path

import numba
import numpy as np
import xarray as xr
from threadpoolctl import threadpool_limits

from .._version import __version__
from ..errors import InputError, StudyError
from ..model.results import Status
from ..output.io import read_netcdf, write_netcdf
from ..output.progress import Progress
from .combine import STATUS_FAILED, STATUS_OK, combine_points
from .files import base_cell, load_study
from .tasks import get_task

__all__ = ["run_study"]




# ------------------------------------------------------------------------------------ tasks


# ------------------------------------------------------------------------------------ study file


# ------------------------------------------------------------------------------------ one point
def _point_cell(path, values):
    if path is None:
        return None
    cell = base_cell(path)
    return cell.replace(**values) if values else cell


def _limit_threads(n: int) -> None:
    try:
        numba.set_num_threads(max(1, min(n, numba.config.NUMBA_NUM_THREADS)))
    except Exception:  # noqa: BLE001 - best effort
        pass
    try:
        threadpool_limits(n)
    except Exception:  # noqa: BLE001
        pass


def _run_point(job: dict) -> dict:
    """Run one study point and write its file atomically; returns {index, status, error, seconds}."""
    if job.get("threads"):  # one point per process: no nested BLAS/numba thread pools
        _limit_threads(int(job["threads"]))
    t0 = time.perf_counter()
    status, error, check = STATUS_OK, "", ""
    try:
        cell = _point_cell(job["cell"], job["cell_values"])
        ds = get_task(job["task"])(cell, **job["options"])
        if not isinstance(ds, xr.Dataset):
            raise InputError(f"task {job['task']!r} returned {type(ds).__name__}, not an xarray Dataset")
        check = str(ds.attrs.get("check", ""))   # a warning the result carries (e.g. a force drop)
        if ds.attrs.get("status", Status.OK.value) != Status.OK.value:
            # a result that ended early (a curve cut short): kept in the point file, failed in the study
            status, error = STATUS_FAILED, f"{ds.attrs['status']}: {ds.attrs.get('status_detail', '')}"
        ds = ds.copy()
        ds.attrs = {}
    except Exception as exc:  # noqa: BLE001 - a failed point is recorded, not raised
        status, error = STATUS_FAILED, f"{type(exc).__name__}: {exc}"
        ds = xr.Dataset()
    seconds = time.perf_counter() - t0
    ds["status"] = ((), np.int8(status), {"units": "1", "long_name": "point status (0 ok, 1 failed)"})
    ds["error"] = ((), error, {"units": "1", "long_name": "error message of a failed point"})
    ds["check"] = ((), check, {"units": "1", "long_name": "warning of the point's result"})
    ds.attrs = {"point_key": job["key"], "index": job["index"], "seconds": seconds,
                "homtex_version": __version__}
    write_netcdf(ds, job["file"])
    return {"index": job["index"], "status": status, "error": error, "seconds": seconds}


def _read_point(path: Path, key: str):
    """The point Dataset if its file exists and belongs to this study point, else None."""
    if not path.exists():
        return None
    try:
        ds = read_netcdf(path)
    except Exception:  # noqa: BLE001 - an unreadable file counts as not done
        return None
    if ds.attrs.get("point_key") != key:
        raise StudyError(f"{path} belongs to a different study or point (key {ds.attrs.get('point_key')!r}, "
                         f"expected {key!r}); use a fresh output folder", file=path)
    return ds


# ------------------------------------------------------------------------------------ executors
class _Serial:
    def __init__(self):
        self.n_workers = 1

    def run(self, fn, jobs):
        for j in jobs:
            yield fn(j)

    def close(self):
        pass


class _Pool:
    def __init__(self, workers):
        self.n_workers = workers
        # fresh interpreters: a fork of a process whose numba / BLAS thread pools already ran
        # (any homtex computation before run_study) kills its workers on their first kernel
        self.ex = ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"))

    def run(self, fn, jobs):
        futs = [self.ex.submit(fn, j) for j in jobs]
        try:
            for f in as_completed(futs):
                yield f.result()
        finally:
            for f in futs:
                f.cancel()

    def close(self):
        self.ex.shutdown(wait=True, cancel_futures=True)


class _Dask:
    def __init__(self, scheduler):
        try:
            from distributed import Client
        except ImportError as exc:
            raise InputError("scheduler given but dask.distributed is not installed "
                             "(pip install 'dask[distributed]')") from exc
        if isinstance(scheduler, Client):
            self.client, self.own = scheduler, False
        else:
            self.client, self.own = Client(scheduler), True
        self.n_workers = max(1, len(self.client.scheduler_info().get("workers", {})))

    def run(self, fn, jobs):
        from distributed import as_completed

        futs = [self.client.submit(fn, j, pure=False, key=f"homtex-point-{j['key']}-{j['index']}") for j in jobs]
        try:
            for f in as_completed(futs):
                yield f.result()
        finally:
            for f in futs:
                f.cancel()

    def close(self):
        if self.own:
            self.client.close()


def _executor(scheduler, workers, n_todo):
    if scheduler is not None:
        return _Dask(scheduler)
    if workers is None:
        workers = min(os.cpu_count() or 1, max(n_todo, 1))
    if int(workers) < 1:
        raise InputError(f"workers must be >= 1, got {workers!r}")
    return _Serial() if int(workers) == 1 else _Pool(int(workers))


class _Progress(Progress):
    """The study's progress: points done, failures noted."""

    def __init__(self, total, done, name, enabled):
        super().__init__(total, f"study {name}", done=done, unit="points", enabled=enabled)

    def step(self, failed: bool):
        super().step("a point failed" if failed else "")


# ------------------------------------------------------------------------------------ combine


# ------------------------------------------------------------------------------------ runner
def run_study(path, out_dir, *, scheduler=None, workers: int | None = None, progress: bool = True,
              max_points: int | None = None, retry_failed: bool = False) -> xr.Dataset:
    """Run (or resume) a study and return its Dataset; writes ``out_dir/result.nc``.

    Parameters
    ----------
    path : study TOML file (see the module docstring).
    out_dir : output folder; ``points/NNNNN.nc`` hold finished points (resume state).
    scheduler : None (local), a dask.distributed scheduler address ("tcp://host:8786") or a
        ``distributed.Client`` (e.g. on a ``LocalCluster``).
    workers : local processes (default: CPU count, capped by the points left); 1 runs in-process.
    progress : show a progress bar (rich) or plain progress lines.
    max_points : stop after this many new points (a budget; the Dataset is then partial with
        ``status`` = -1 for points not run and ``attrs["complete"]`` = 0, and result.nc is
        not written).
    retry_failed : run failed points again instead of keeping their recorded error.

    Returns
    -------
    xarray.Dataset: the task's variables over the grid parameters (dimensions) or over
    ``sample``; ``status`` and ``error`` per point; cell definition, study and version in attrs.
    """
    study = load_study(path)
    out = Path(out_dir)
    (out / "points").mkdir(parents=True, exist_ok=True)
    for tmp in (out / "points").glob(".*.tmp"):  # leftovers of a killed write
        try:
            tmp.unlink()
        except OSError:
            pass
    jobs = [study.job(i, out) for i in range(study.n_points)]
    points = [_read_point(Path(j["file"]), j["key"]) for j in jobs]
    todo = [j for j, p in zip(jobs, points)
            if p is None or (retry_failed and int(p["status"]) == STATUS_FAILED)]
    if max_points is not None:
        todo = todo[:max(int(max_points), 0)]
    bar = _Progress(study.n_points, study.n_points - len([p for p in points if p is None]) if not retry_failed
                    else study.n_points - len(todo), study.name, progress)
    if todo:
        ex = _executor(scheduler, workers, len(todo))
        if isinstance(ex, _Pool):  # share the cores between the worker processes
            per = max(1, (os.cpu_count() or 1) // ex.n_workers)
            todo = [{**j, "threads": per} for j in todo]
        try:
            for res in ex.run(_run_point, todo):
                bar.step(res["status"] != STATUS_OK)
        except BrokenExecutor as exc:
            # a worker died without a Python error (killed for memory, a crash in native code):
            # which point it ran is unknown, so nothing is recorded as failed; finished points stay
            done = sum(_read_point(Path(j["file"]), j["key"]) is not None for j in jobs)
            raise StudyError(f"a worker process died ({exc}); {done} of {study.n_points} points are "
                             f"finished and kept in {out / 'points'}; run the study again to resume "
                             "(fewer workers if memory ran out)", file=path) from exc
        finally:
            ex.close()
            bar.close()
    else:
        bar.close()
    points = [_read_point(Path(j["file"]), j["key"]) for j in jobs]
    ds = combine_points(study, points)
    if ds.attrs["complete"]:
        write_netcdf(ds, out / "result.nc")
    return ds
