"""Running a study: every point an independent job, results written atomically, resumable.

Every point is an independent job ``_run_point(job)`` that writes
``out_dir/points/NNNNN.nc`` atomically (temp file + ``os.replace``), so a killed study
resumes where it stopped: finished point files are skipped. A point whose task raises is
recorded (``status`` = 1, ``error`` = message, its values masked) and the others complete;
a rerun retries the failed points (``keep_failed=True`` keeps their recorded errors).
Executors: in-process for ``workers=1``, a local process pool by default, dask.distributed
when ``scheduler`` is an address or a ``distributed.Client`` (same job function).

Point files are verified before they are reused: each carries the SHA-256 of its data
(:func:`point_checksum`, attribute ``point_sha256``). A point file that cannot be read, has
no checksum or whose data no longer match it (a truncated file, numbers edited by hand or
by a tool) is reported (a logged warning naming the file), moved aside to
``points/NNNNN.nc.bad`` for inspection, and its point runs again. Running it again rather
than stopping is safe: a point file is a cache of a deterministic computation, and the
rerun writes what the task gives; stopping would only make the user delete the file by hand.

The combined Dataset is always assembled from the point files, so a resumed study gives a
Dataset identical to an uninterrupted one. Per-point wall times stay in the point files'
attributes (``seconds``), not in the combined Dataset.

Problems of the output folder (a file, not writable, a full disk) and an unreachable dask
scheduler are a :class:`~homtex.errors.StudyError` (an InputError) with one line that names
the folder or address and what to do; points finished before a full disk stay valid and a
rerun resumes.
"""

from __future__ import annotations

import hashlib
import json
import logging
import multiprocessing
import os
import socket
import time
import warnings
from concurrent.futures import BrokenExecutor, ProcessPoolExecutor, as_completed
from pathlib import Path

import numba
import numpy as np
import xarray as xr
from threadpoolctl import threadpool_limits

from .._version import __version__
from ..errors import InputError, StudyError
from ..model.results import Status
from ..output.io import read_netcdf, write_failure, write_netcdf
from ..output.progress import Progress
from .combine import STATUS_FAILED, STATUS_OK, combine_points
from .files import base_cell, load_study
from .tasks import ENTRY_POINT_GROUP, get_task, in_process_only

__all__ = ["point_checksum", "run_study", "summarize"]

log = logging.getLogger(__name__)

#: seconds to wait for a dask scheduler to answer before the study stops with an error
CONNECT_TIMEOUT = 5.0


# ------------------------------------------------------------------------------------ checksums
def _canonical(values) -> bytes:
    """Bytes of an array that survive a netCDF round trip unchanged (strings as UTF-8 JSON,
    booleans as int8 like :func:`write_netcdf`, every NaN the same NaN, little-endian)."""
    a = np.asarray(values)
    if a.dtype.kind in "OUST":
        items = [x.decode("utf-8", "replace") if isinstance(x, bytes) else str(x) for x in a.ravel().tolist()]
        return b"str" + json.dumps(items, ensure_ascii=False).encode("utf-8")
    if a.dtype.kind == "b":
        a = a.astype(np.int8)
    elif a.dtype.kind == "M":
        a = a.astype("datetime64[ns]").view(np.int64)
    elif a.dtype.kind == "m":
        a = a.astype("timedelta64[ns]").view(np.int64)
    elif a.dtype.kind in "fc":
        a = np.where(np.isnan(a), np.nan, a).astype(a.dtype)
    a = np.ascontiguousarray(a, dtype=a.dtype.newbyteorder("<"))
    return f"{a.dtype.kind}{a.dtype.itemsize}".encode() + a.tobytes()


def point_checksum(ds) -> str:
    """SHA-256 (hex) over the names, dimensions, shapes and values of every variable and
    coordinate of ``ds`` (attributes are not covered); the same before writing and after
    reading back a netCDF file."""
    h = hashlib.sha256()
    for name in sorted(map(str, ds.variables)):
        v = ds.variables[name]
        h.update(json.dumps([name, [str(d) for d in v.dims], list(v.shape)]).encode())
        h.update(_canonical(v.values))
    return h.hexdigest()


# ------------------------------------------------------------------------------------ output folder
def _output_error(folder: Path, exc: BaseException) -> StudyError:
    """One line for a write that failed in the output folder: not writable (the error number says
    permission or read-only, whatever the disk's free space), full, or else
    (:func:`homtex.output.io.write_failure`)."""
    kind, cause = write_failure(folder, exc)
    reason = getattr(exc, "strerror", None) or cause
    if kind == "refused":
        msg = (f"the output folder {folder} is not writable ({reason}): make it writable or give "
               "another output folder")
    elif kind == "full":
        msg = (f"the disk holding the output folder {folder} is full ({reason}): free some space or give "
               "another output folder, then run the study again")
    else:
        msg = f"cannot write to the output folder {folder} ({type(exc).__name__}: {reason})"
    return StudyError(msg)


def _prepare_out_dir(out: Path) -> None:
    """Check up front that ``out`` is, or can be made, a writable folder (StudyError if not)."""
    if out.exists() and not out.is_dir():
        raise StudyError(f"the output folder {out} is a file, not a folder: give a folder (it is created "
                         "if missing)")
    try:
        (out / "points").mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise StudyError(f"{out / 'points'} (or a parent of it) is a file, not a folder: give another "
                         "output folder") from None
    except OSError as exc:
        raise _output_error(out, exc) from None
    probe = out / "points" / f".write-probe-{os.getpid()}.tmp"
    try:
        fd = os.open(probe, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        try:
            os.write(fd, b"homtex")
            os.fsync(fd)
        finally:
            os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        try:
            probe.unlink()
        except OSError:
            pass
        raise _output_error(out, exc) from None
    for tmp in (out / "points").glob(".*.tmp"):  # leftovers of a killed write
        try:
            tmp.unlink()
        except OSError:
            pass


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
    """Run one study point and write its file atomically; returns {index, status, error, seconds}.

    A task that raises, returns no Dataset or one that cannot be written to netCDF makes a
    failed point; a write that fails in the output folder (full disk, permissions) raises a
    StudyError (the study stops; finished points stay).
    """
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
    folder = Path(job["file"]).parent.parent
    try:
        _write_point(ds, job, status, error, check, seconds)
    except OSError as exc:
        raise _output_error(folder, exc) from None
    except Exception as exc:  # noqa: BLE001 - the task's Dataset cannot be stored: a failed point
        status, error = STATUS_FAILED, f"the task's Dataset cannot be written to netCDF: {type(exc).__name__}: {exc}"
        try:
            _write_point(xr.Dataset(), job, status, error, check, seconds)
        except Exception as exc2:  # noqa: BLE001
            raise _output_error(folder, exc2) from None
    return {"index": job["index"], "status": status, "error": error, "seconds": seconds}


def _write_point(ds, job, status, error, check, seconds) -> None:
    ds = ds.copy()
    ds["status"] = ((), np.int8(status), {"units": "1", "long_name": "point status (0 ok, 1 failed)"})
    ds["error"] = ((), error, {"units": "1", "long_name": "error message of a failed point"})
    ds["check"] = ((), check, {"units": "1", "long_name": "warning of the point's result"})
    ds.attrs = {"point_key": job["key"], "index": job["index"], "seconds": seconds,
                "homtex_version": __version__, "point_sha256": point_checksum(ds)}
    write_netcdf(ds, job["file"])


def _set_aside(path: Path, why: str) -> None:
    """Report a point file that cannot be trusted and move it to ``NNNNN.nc.bad``."""
    bad = path.with_name(path.name + ".bad")
    try:
        os.replace(path, bad)
    except OSError as exc:
        raise StudyError(f"point file {path} {why}, and it cannot be moved aside ({exc.strerror or exc}): "
                         "delete it and run the study again") from None
    log.warning("point file %s %s: moved to %s; the point runs again", path, why, bad.name)


def _read_point(path: Path, key: str, *, verify: bool = True):
    """The point Dataset if its file exists, belongs to this study point and matches its
    checksum; None if there is no file or it could not be trusted (then reported and moved
    aside, see the module docstring). StudyError if it belongs to another study."""
    if not path.exists():
        return None
    try:
        ds = read_netcdf(path)
    except Exception as exc:  # noqa: BLE001 - any reason a file cannot be read
        if not verify:
            return None
        _set_aside(path, f"cannot be read ({type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''})")
        return None
    if ds.attrs.get("point_key") != key:
        raise StudyError(f"{path} belongs to a different study or point (key {ds.attrs.get('point_key')!r}, "
                         f"expected {key!r}); use a fresh output folder", file=path)
    if verify:
        stored = ds.attrs.get("point_sha256")
        if stored is None:
            _set_aside(path, "has no checksum (written by an older homtex, or its attributes were edited)")
            return None
        if point_checksum(ds) != stored:
            _set_aside(path, "does not match its checksum (its data were changed after it was written)")
            return None
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
    def __init__(self, scheduler, timeout: float = CONNECT_TIMEOUT):
        try:
            from distributed import Client
        except ImportError as exc:
            raise InputError("scheduler given but dask.distributed is not installed "
                             "(pip install 'dask[distributed]')") from exc
        if isinstance(scheduler, Client):
            self.client, self.own = scheduler, False
        else:
            try:
                _probe_scheduler(scheduler, timeout)
                self.client, self.own = Client(scheduler, timeout=timeout, set_as_default=False), True
            except Exception as exc:  # noqa: BLE001 - refused, timed out, a bad address: one line
                first = (str(exc).splitlines() or [type(exc).__name__])[0]
                raise StudyError(f"cannot reach the dask scheduler at {scheduler!r} ({type(exc).__name__}: "
                                 f"{first}; connect timeout {timeout:g} s): start it (dask scheduler), check the "
                                 "address, or run without a scheduler (local processes)") from None
        self.n_workers = len(self.client.scheduler_info().get("workers", {}))
        if self.n_workers == 0:
            log.warning("the dask scheduler %s has no workers yet: the points wait until workers join",
                        getattr(self.client.scheduler, "address", scheduler))
        self.n_workers = max(1, self.n_workers)

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


def _probe_scheduler(address, timeout: float) -> None:
    """Check a scheduler address before a Client is made: a plain TCP connect (a refused port or
    an unknown host fail at once, an unroutable one after ``timeout``), then, for tcp://, a dask
    ``identity`` call with a deadline (a Client waits forever on a peer that accepts but never
    answers) that also tells a worker's address from the scheduler's."""
    from distributed.comm import parse_address, parse_host_port

    if not isinstance(address, str):
        raise TypeError(f"a scheduler address is a string such as 'tcp://host:8786', got {address!r}")
    scheme, location = parse_address(address)
    if scheme not in ("tcp", "tls"):
        return
    host, port = parse_host_port(location)
    with socket.create_connection((host, int(port)), timeout=timeout):
        pass
    if scheme != "tcp":  # tls needs the security settings; the Client checks the rest
        return
    answer = _identity(address, timeout)
    kind = answer.get("type") if isinstance(answer, dict) else None
    if kind != "Scheduler":
        raise ConnectionError(f"the address answers as a dask {kind}, not as the scheduler" if kind else
                              "the address does not answer as a dask scheduler")


def _identity(address: str, timeout: float):
    """The dask ``identity`` of ``address``, asked from a thread with its own event loop (the
    caller may run inside one, e.g. Jupyter); TimeoutError after ``timeout`` seconds."""
    import asyncio
    import threading

    from distributed.core import rpc

    out: dict = {}

    async def ask():
        r = rpc(address, timeout=timeout)
        try:
            return await asyncio.wait_for(r.identity(), timeout)
        finally:
            await r.close_rpc()

    def run():
        try:
            out["answer"] = asyncio.run(ask())
        except BaseException as exc:  # noqa: BLE001 - handed to the caller
            out["error"] = exc

    t = threading.Thread(target=run, name="homtex-scheduler-probe", daemon=True)
    t.start()
    t.join(timeout + 2.0)
    if "error" in out:
        if isinstance(out["error"], (TimeoutError, asyncio.TimeoutError)):
            raise TimeoutError(f"no answer from a dask scheduler within {timeout:g} s")
        raise out["error"]
    if "answer" not in out:
        raise TimeoutError(f"no answer from a dask scheduler within {timeout:g} s")
    return out["answer"]


def _executor(scheduler, workers, n_todo, task: str, timeout: float):
    local_only = in_process_only(task)
    if local_only and (scheduler is not None or (workers is not None and int(workers) > 1)):
        raise StudyError(f"task {task!r} is registered in this process only (register_task): worker "
                         f"processes cannot find it. Run with workers=1 and no scheduler, or declare it "
                         f"in the entry point group {ENTRY_POINT_GROUP!r} of an installed package",
                         table="study", key="task")
    if scheduler is not None:
        return _Dask(scheduler, timeout)
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, (int, np.integer))
                                or int(workers) < 1):
        raise InputError(f"workers must be an integer >= 1, got {workers!r}")
    if workers is None:
        if local_only:
            log.warning("task %r is registered in this process only (register_task): its points run here, "
                        "one at a time; declare it in the entry point group %r to use worker processes",
                        task, ENTRY_POINT_GROUP)
            workers = 1
        else:
            workers = min(os.cpu_count() or 1, max(n_todo, 1))
    return _Serial() if int(workers) == 1 else _Pool(int(workers))


class _Progress(Progress):
    """The study's progress: points done, failures noted."""

    def __init__(self, total, done, name, enabled):
        super().__init__(total, f"study {name}", done=done, unit="points", enabled=enabled)

    def step(self, failed: bool):
        super().step("a point failed" if failed else "")


# ------------------------------------------------------------------------------------ summary
def summarize(ds) -> str:
    """One line on a study Dataset's points: "12 of 12 points ok", or
    "3 of 12 points failed: <first error> (point 9: x = 3)" (plus points not run)."""
    n = int(ds.attrs.get("points_total", ds["status"].size))
    n_failed, n_not_run = int(ds.attrs.get("points_failed", 0)), int(ds.attrs.get("points_not_run", 0))
    status = ds["status"].values.ravel()
    parts = []
    if n_failed:
        status_all = ds["status"]
        i = int(np.flatnonzero(status == STATUS_FAILED)[0])
        point = status_all[np.unravel_index(i, status_all.shape)]   # scalar coords: the parameters
        names = [k for k in json.loads(ds.attrs.get("study_parameters", "[]")) if k in point.coords]
        where = ", ".join(f"{k} = {_fmt(point[k].values.item())}" for k in names)
        first = (str(ds["error"].values.ravel()[i]).strip().splitlines() or ["(no message)"])[0]
        parts.append(f"{n_failed} of {n} points failed: {first}"
                     + (f" (first failed point: {where})" if where else ""))
    if n_not_run:
        parts.append(f"{n_not_run} of {n} points not run yet")
    if not parts:
        return f"{n - n_failed - n_not_run} of {n} points ok"
    return "; ".join(parts)


def _fmt(v) -> str:
    return f"{v:g}" if isinstance(v, float) else str(v)


# ------------------------------------------------------------------------------------ runner
def run_study(path, out_dir, *, scheduler=None, workers: int | None = None, progress: bool = True,
              max_points: int | None = None, keep_failed: bool = False, retry_failed: bool | None = None,
              connect_timeout: float = CONNECT_TIMEOUT) -> xr.Dataset:
    """Run (or resume) a study and return its Dataset; writes ``out_dir/result.nc``.

    Parameters
    ----------
    path : study TOML file (see :mod:`homtex.study.files`).
    out_dir : output folder (created if missing); ``points/NNNNN.nc`` hold finished points
        (the resume state, each verified by its checksum before it is reused).
    scheduler : None (local), a dask.distributed scheduler address ("tcp://host:8786") or a
        ``distributed.Client`` (e.g. on a ``LocalCluster``).
    workers : local processes (default: CPU count, capped by the points left); 1 runs in-process.
    progress : show a progress bar (rich) or plain progress lines.
    max_points : stop after this many new points (a budget; the Dataset is then partial with
        ``status`` = -1 for points not run and ``attrs["complete"]`` = 0, and result.nc is
        not written).
    keep_failed : keep the recorded error of points that failed in an earlier run instead of
        running them again (the default retries them).
    retry_failed : deprecated (retrying is the default now); ``True`` is the default behaviour,
        ``False`` means ``keep_failed=True``. Gives a DeprecationWarning.
    connect_timeout : seconds to wait for the dask ``scheduler`` (an address) to answer.

    Returns
    -------
    xarray.Dataset: the task's variables (with the task's units) over the grid parameters
    (dimensions) or over ``sample``; ``status`` (0 ok, 1 failed, -1 not run), ``error`` and
    ``check`` per point; ``attrs`` points_ok / points_failed / points_not_run / complete,
    the cell definition, study and version.

    When all points have run, ``out_dir/result.nc`` is written, also when some points failed:
    their values are masked (NaN) and ``status``/``error`` say which and why. A summary line
    ("3 of 12 points failed: <first error> ...", :func:`summarize`) is logged at WARNING when
    points failed; ``homtex study`` then exits with status 1.

    Raises
    ------
    StudyError (an InputError): a bad study file, an output folder that is a file, not
    writable or full (finished points stay; run again to resume), an unreachable scheduler,
    a task registered in this process only with workers > 1 or a scheduler, a point file of
    another study, a worker process that died.
    """
    if retry_failed is not None:
        warnings.warn("run_study(retry_failed=...) is deprecated: failed points are retried by default; "
                      "use keep_failed=True to keep their recorded errors", DeprecationWarning, stacklevel=2)
        if retry_failed and keep_failed:
            raise InputError("retry_failed=True and keep_failed=True contradict each other; give keep_failed only")
        keep_failed = keep_failed or not retry_failed
    if max_points is not None and (isinstance(max_points, bool) or not isinstance(max_points, (int, np.integer))):
        raise InputError(f"max_points must be an integer, got {max_points!r}")
    if not (isinstance(connect_timeout, (int, float)) and not isinstance(connect_timeout, bool)
            and connect_timeout > 0):
        raise InputError(f"connect_timeout must be a number of seconds > 0, got {connect_timeout!r}")
    study = load_study(path)
    out = Path(out_dir)
    _prepare_out_dir(out)
    jobs = [study.job(i, out) for i in range(study.n_points)]
    points = [_read_point(Path(j["file"]), j["key"]) for j in jobs]
    todo = [j for j, p in zip(jobs, points)
            if p is None or (not keep_failed and int(p["status"]) == STATUS_FAILED)]
    n_kept = study.n_points - len(todo)
    if max_points is not None:
        todo = todo[:max(int(max_points), 0)]
    ex = _executor(scheduler, workers, len(todo), study.task, float(connect_timeout)) if todo else None
    bar = _Progress(study.n_points, n_kept, study.name, progress)
    if ex is not None:
        if isinstance(ex, _Pool):  # share the cores between the worker processes
            per = max(1, (os.cpu_count() or 1) // ex.n_workers)
            todo = [{**j, "threads": per} for j in todo]
        try:
            for res in ex.run(_run_point, todo):
                bar.step(res["status"] != STATUS_OK)
        except BrokenExecutor as exc:
            # a worker died without a Python error (killed for memory, a crash in native code):
            # which point it ran is unknown, so nothing is recorded as failed; finished points stay
            raise StudyError(f"a worker process died ({exc}); {_n_done(jobs)} of {study.n_points} points are "
                             f"finished and kept in {out / 'points'}; run the study again to resume "
                             "(fewer workers if memory ran out)", file=path) from None
        except StudyError as exc:  # the output folder failed (full disk, permissions)
            raise StudyError(f"{exc}; {_n_done(jobs)} of {study.n_points} points are finished and kept in "
                             f"{out / 'points'}; run the study again to resume") from None
        finally:
            ex.close()
            bar.close()
    else:
        bar.close()
    points = [_read_point(Path(j["file"]), j["key"]) for j in jobs]
    ds = combine_points(study, points)
    if ds.attrs["complete"]:
        try:
            write_netcdf(ds, out / "result.nc")
        except Exception as exc:  # noqa: BLE001 - the points wrote fine: the folder or disk failed
            raise StudyError(f"{_output_error(out, exc)}; all {study.n_points} points are finished and kept in "
                             f"{out / 'points'}; run the study again to write result.nc") from None
    if ds.attrs["points_failed"]:
        log.warning("study %s: %s", study.name, summarize(ds))
    return ds


def _n_done(jobs) -> int:
    """Point files now on disk that can be read and belong to their point (not verified)."""
    n = 0
    for j in jobs:
        try:
            n += _read_point(Path(j["file"]), j["key"], verify=False) is not None
        except StudyError:
            pass
    return n
