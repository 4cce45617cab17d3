"""The ``homtex`` command: one subcommand per pipeline stage, each writing netCDF + PNG.

    homtex run      [--out DIR]                 the main job (README's first command)
    homtex cell     CELL [--out DIR]            summary and picture of a unit cell
    homtex homogenize CELL [--out DIR]          effective stiffness of a periodic cell
    homtex compress CELL [--strain 0.3] [--steps 20] [--out DIR]
    homtex seam     CELL --distance D [--prestrain EPS] [--out DIR]
    homtex macro    CELL [--distance D] [--scatter S] [--pre-stress LAW] [--slack-travel MM] [--out DIR]
    homtex study    STUDY.toml --out DIR [--scheduler ADDRESS]
    homtex plot     FILE.nc [--out PNG]

Errors from bad input (InputError) and failed solves (SolverError) are printed as one clear
message and a non-zero exit status, never as a traceback.
"""

from __future__ import annotations

import argparse
import logging
import sys
import time
from pathlib import Path

from .._version import __version__
from ..errors import InputError, SolverError
from ..study import run_study
from .commands import cell_summary, compress_cell, homogenize_cell, macro_cell, plot_file, seam_cell
from .main_job import main_job

log = logging.getLogger("homtex")


def _out(args, default: str) -> Path:
    out = Path(args.out or default)
    out.mkdir(parents=True, exist_ok=True)
    return out


def _say(msg: str) -> None:
    print(msg, flush=True)


def cmd_run(args) -> None:
    t0 = time.perf_counter()
    outputs = main_job(_out(args, "results"), quick=args.quick)
    _say(f"\nmain job finished in {time.perf_counter() - t0:.1f} s; outputs:")
    for name, path in outputs.items():
        _say(f"  {name:<28s} {path}")


def cmd_cell(args) -> None:
    for name, path in cell_summary(args.cell, _out(args, "results/cell")).items():
        _say(f"  {name:<20s} {path}")


def cmd_homogenize(args) -> None:
    ds, paths = homogenize_cell(args.cell, _out(args, "results/homogenize"), solver=args.solver)
    _say(str(ds))
    for p in paths:
        _say(f"  wrote {p}")


def cmd_compress(args) -> None:
    ds, paths = compress_cell(args.cell, _out(args, "results/compress"), strain=args.strain,
                              steps=args.steps)
    _say(str(ds))
    for p in paths:
        _say(f"  wrote {p}")


def cmd_seam(args) -> None:
    ds, paths = seam_cell(args.cell, _out(args, "results/seam"), seam_distance=args.distance,
                          prestrain=args.prestrain, method=args.method)
    _say(f"cushion height {float(ds['cushion_height']):.2f} mm, seam line {float(ds['seam_height']):.2f} mm "
         f"({ds.attrs['method']} model, eps0 = {float(ds['prestrain']):.3g}, status {ds.attrs.get('status', 'ok')})")
    _say(f"  note: {ds.attrs['validity']}")
    for p in paths:
        _say(f"  wrote {p}")


def cmd_macro(args) -> None:
    ds, paths = macro_cell(args.cell, _out(args, "results/macro"), seam_distance=args.distance,
                           height_scatter=args.scatter, seed=args.seed, pre_stress=args.pre_stress,
                           slack_travel=args.slack_travel, seam_method=args.seam_method)
    _say(str(ds))
    for p in paths:
        _say(f"  wrote {p}")


def cmd_study(args) -> None:
    """Run or resume a study. Exit status: 0 all points ok; 1 some points failed (result.nc is
    still written, with ``status``/``error`` per point; a rerun retries them unless
    --keep-failed); 2 bad input (study file, output folder, scheduler), via main()."""
    from ..study import summarize

    ds = run_study(args.study, args.out, scheduler=args.scheduler, workers=args.workers,
                   keep_failed=args.keep_failed, connect_timeout=args.connect_timeout)
    _say(str(ds))
    result = Path(args.out) / "result.nc"
    n_failed = int(ds.attrs["points_failed"])
    if ds.attrs["complete"]:
        note = (f" (the {n_failed} failed points are NaN there; 'status' and 'error' say which and why)"
                if n_failed else "")
        _say(f"  wrote {result}{note}")
    else:
        _say(f"  {result} not written: the study is not complete")
    if n_failed or not ds.attrs["complete"]:
        print(f"homtex study: error: {summarize(ds)}"
              + ("; run the same command again to retry the failed points" if n_failed and not args.keep_failed
                 else ""), file=sys.stderr)
        raise SystemExit(1)


def cmd_plot(args) -> None:
    _say(f"  wrote {plot_file(args.file, args.out)}")


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="homtex", description=__doc__.split("\n")[0])
    p.add_argument("--version", action="version", version=f"homtex {__version__}")
    sub = p.add_subparsers(dest="command", required=True)

    s = sub.add_parser("run", help="the main job: the paper's study end to end")
    s.add_argument("--out", help="output folder (default results/)")
    s.add_argument("--quick", action="store_true", help="coarser, faster variant (for smoke tests)")
    s.set_defaults(func=cmd_run)

    s = sub.add_parser("cell", help="summary and picture of a unit cell")
    s.add_argument("cell")
    s.add_argument("--out")
    s.set_defaults(func=cmd_cell)

    s = sub.add_parser("homogenize", help="effective stiffness of a periodic cell")
    s.add_argument("cell")
    s.add_argument("--solver", default="amg", choices=["amg", "direct", "cg"])
    s.add_argument("--out")
    s.set_defaults(func=cmd_homogenize)

    s = sub.add_parser("compress", help="compression curve of a fabric cell between plates")
    s.add_argument("cell")
    s.add_argument("--strain", type=float, default=0.3)
    s.add_argument("--steps", type=int, default=20)
    s.add_argument("--out")
    s.set_defaults(func=cmd_compress)

    s = sub.add_parser("seam", help="cushion profile of a seam cell")
    s.add_argument("cell")
    s.add_argument("--distance", type=float, required=True, help="seam distance, mm")
    s.add_argument("--prestrain", type=float, default=None,
                   help="stitch-yarn pre-strain (default: the cell file's value for the method)")
    s.add_argument("--method", choices=("yarn", "foundation"), default="yarn",
                   help="yarn-level seam cell (default) or the analytical foundation model")
    s.add_argument("--out")
    s.set_defaults(func=cmd_seam)

    s = sub.add_parser("macro", help="force-compression curve of a seamed specimen (cushion layer)")
    s.add_argument("cell")
    s.add_argument("--distance", type=float, default=None, help="seam distance, mm (default: no seams)")
    s.add_argument("--scatter", type=float, default=0.0, help="height scatter between cushions")
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("--pre-stress", choices=("thread", "held", "released"), default="thread",
                   help="who carries a pre-compressed cushion's pre-load under the punch (default: the thread "
                   "hands it over within its slack travel)")
    s.add_argument("--slack-travel", type=float, default=None,
                   help="thread slack travel, mm (default: from the seam profile)")
    s.add_argument("--seam-method", choices=("yarn", "foundation"), default="yarn",
                   help="seam model that gives the cushion profile (default: the yarn-level seam cell)")
    s.add_argument("--out")
    s.set_defaults(func=cmd_macro)

    s = sub.add_parser("study", help="run a parameter study (resumable)",
                       description="Run or resume a parameter study. Exit status 0: all points ok; 1: points "
                       "failed (result.nc is written with status and error per point; a rerun retries them); "
                       "2: bad input (study file, output folder, scheduler).")
    s.add_argument("study", help="study file (.toml)")
    s.add_argument("--out", required=True, help="output folder (created if missing; holds points/ and result.nc)")
    s.add_argument("--scheduler", default=None, help="dask.distributed scheduler address (tcp://host:8786)")
    s.add_argument("--connect-timeout", type=float, default=5.0, metavar="SECONDS",
                   help="seconds to wait for the scheduler to answer (default 5)")
    s.add_argument("--workers", type=int, default=None,
                   help="local worker processes (default: one per core; 1 runs in this process)")
    s.add_argument("--keep-failed", action="store_true",
                   help="keep the recorded errors of points that failed in an earlier run (default: retry them)")
    s.set_defaults(func=cmd_study)

    s = sub.add_parser("plot", help="chart of a homtex netCDF file")
    s.add_argument("file")
    s.add_argument("--out", default=None)
    s.set_defaults(func=cmd_plot)
    return p


def _log_to_console() -> logging.Handler:
    """INFO and above from the homtex loggers on stdout (what a long stage is doing)."""
    handler = logging.StreamHandler(sys.stdout)
    handler.setFormatter(logging.Formatter("%(message)s"))
    log.addHandler(handler)
    log.setLevel(logging.INFO)
    return handler


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    handler = _log_to_console()
    try:
        args.func(args)
    except (InputError, SolverError, FileNotFoundError) as exc:
        print(f"homtex {args.command}: error: {exc}", file=sys.stderr)
        return 2
    finally:
        log.removeHandler(handler)
    return 0


if __name__ == "__main__":
    sys.exit(main())
