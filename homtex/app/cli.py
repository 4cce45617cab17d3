"""The ``homtex`` command: one subcommand per pipeline stage, each writing netCDF + PNG.

    homtex run      [--out DIR] [--quick]       the main job (README's first command)
    homtex cell     CELL [--out DIR]            summary and picture of a unit cell
    homtex homogenize CELL [--solver S] [--out DIR]   effective stiffness of a periodic cell
    homtex compress CELL [--strain 0.3] [--steps 20] [--geometry nonlinear|linear] [--friction MU] [--out DIR]
    homtex seam     CELL --distance D [--prestrain EPS] [--method yarn|foundation] [--out DIR]
    homtex macro    CELL [--distance D] [--steps 35 | --curve FILE.nc] [--law columns|cushion] [--strain 0.5] ...
    homtex tensile  CELL --direction wale|course --strain S [--steps N] [--friction MU] [--out DIR]
    homtex study    STUDY.toml --out DIR [--scheduler ADDRESS] [--workers N] [--keep-failed] [--connect-timeout S]
    homtex plot     FILE.nc [--out IMAGE] [--var NAME] [--sel DIM=VALUE]
    homtex cache    [--clear]                   what the result cache holds (sewn seams, laws), or empty it

CELL is a cell file path (.toml) or a shipped cell name (spacer_20mm, octet, ...).
Exit status: 0 done (a result whose checks flag it, ``status`` "flagged", prints a warning line
and still exits 0); 1 a computation that failed (a curve or profile with ``status`` "failed":
its files are written and the reason printed; a study with failed points); 2 a user's mistake
(a bad option, file, folder or value: one line ``homtex <cmd>: error: ...``, never a traceback;
``homtex --debug ...`` shows it); 3 an internal error (run it again with --debug and report it);
130 interrupted (Ctrl-C, also while the modules load: one line).

The stage modules (numpy, numba, scipy, xarray, matplotlib: seconds to import) are imported by
the command that needs them, inside :func:`main`, so that ``--help`` is quick and an interrupt
while they load is caught like any other.
"""

from __future__ import annotations

import argparse
import difflib
import logging
import math
import re
import sys
import time
from pathlib import Path

from .._version import __version__
from ..errors import InputError, SolverError
from .paths import output_folder

log = logging.getLogger("homtex")

CELL_HELP = ("a cell file path (.toml) or a shipped cell name (spacer_20mm, octet, square, honeycomb, ...; "
             "a wrong name lists them all)")


def _out(args, default: str) -> Path:
    return output_folder(args.out or default)


def _say(msg: str) -> None:
    print(msg, flush=True)


def _check_status(args, ds) -> None:
    """The status of a result Dataset on the console: "failed" prints its reason and exits with
    status 1 (the files are already written), "flagged" prints a warning line (exit status 0)."""
    status = str(ds.attrs.get("status", "ok"))
    detail = str(ds.attrs.get("status_detail", "")) or "no detail recorded"
    if status == "failed":
        print(f"homtex {args.command}: failed: {detail} (what was computed before it is written)", file=sys.stderr)
        raise SystemExit(1)
    if status == "flagged":
        print(f"homtex {args.command}: warning: the result is flagged: {detail}", file=sys.stderr)


def cmd_run(args) -> None:
    from .main_job import main_job

    t0 = time.perf_counter()
    outputs = main_job(_out(args, "results"), quick=args.quick, workers=args.workers)
    _say(f"\nmain job finished in {time.perf_counter() - t0:.1f} s; outputs:")
    for name, path in outputs.items():
        _say(f"  {name:<28s} {path}")


def cmd_cell(args) -> None:
    from .commands import cell_summary

    for name, path in cell_summary(args.cell, _out(args, "results/cell")).items():
        _say(f"  {name:<20s} {path}")


def cmd_homogenize(args) -> None:
    from .commands import homogenize_cell, homogenize_summary

    ds, paths = homogenize_cell(args.cell, _out(args, "results/homogenize"), solver=args.solver)
    _say(homogenize_summary(ds))
    for p in paths:
        _say(f"  wrote {p}")
    _check_status(args, ds)


def cmd_compress(args) -> None:
    if args.friction and args.geometry == "linear":
        raise InputError(f"--friction {args.friction:g} needs the large-motion engine (--geometry nonlinear, the "
                         "default): the linear contact solve is frictionless")
    from .commands import compress_cell

    ds, paths, line = compress_cell(args.cell, _out(args, "results/compress"), strain=args.strain,
                                    steps=args.steps, geometry=args.geometry, friction=args.friction)
    _say(line)
    for p in paths:
        _say(f"  wrote {p}")
    _check_status(args, ds)


def cmd_seam(args) -> None:
    from .commands import seam_cell

    ds, paths = seam_cell(args.cell, _out(args, "results/seam"), seam_distance=args.distance,
                          prestrain=args.prestrain, method=args.method)
    _say(f"cushion height {float(ds['cushion_height']):.2f} mm, seam line {float(ds['seam_height']):.2f} mm "
         f"({ds.attrs['method']} model, eps0 = {float(ds['prestrain']):.3g}, seams every "
         f"{float(ds.attrs.get('effective_seam_distance_mm', args.distance)):.4g} mm, "
         f"status {ds.attrs.get('status', 'ok')})")
    _say(f"  note: {ds.attrs['validity']}")
    for p in paths:
        _say(f"  wrote {p}")
    _check_status(args, ds)


def cmd_macro(args) -> None:
    if args.curve is not None and args.steps is not None:
        raise InputError("give either --steps (compute the compression law) or --curve (a stored one), not both")
    from .commands import macro_cell

    ds, paths, line = macro_cell(args.cell, _out(args, "results/macro"), seam_distance=args.distance,
                                 height_scatter=args.scatter, seed=args.seed, pre_stress=args.pre_stress,
                                 slack_travel=args.slack_travel, seam_method=args.seam_method,
                                 steps=args.steps, strain=args.strain,
                                 curve=args.curve, law=args.law)
    for p in paths:
        _say(f"  wrote {p}")
    _check_status(args, ds)


def cmd_tensile(args) -> None:
    from .commands import tensile_cell

    ds, paths, _ = tensile_cell(args.cell, _out(args, "results/tensile"), strain=args.strain,
                                direction=args.direction, steps=args.steps, friction=args.friction)
    for p in paths:
        _say(f"  wrote {p}")
    _check_status(args, ds)


def cmd_study(args) -> None:
    """Run or resume a study. Exit status: 0 all points ok; 1 some points failed (result.nc is
    still written, with ``status``/``error`` per point; a rerun retries them unless
    --keep-failed); 2 bad input (study file, output folder, scheduler), via main()."""
    from ..study import run_study, summarize

    ds = run_study(args.study, args.out, scheduler=args.scheduler, workers=args.workers,
                   keep_failed=args.keep_failed, connect_timeout=args.connect_timeout)
    dims = ", ".join(f"{k} {v}" for k, v in ds.sizes.items())
    _say(f"study {Path(args.study).stem}: {summarize(ds)} (dimensions: {dims})")
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
    from .commands import plot_file

    _say(f"  wrote {plot_file(args.file, args.out, var=args.var, sel=args.sel)}")


def cmd_cache(args) -> None:
    from ..cache import cache_dir, clear_cache, list_cache

    if args.clear:
        _say(f"  removed {clear_cache()} cached result(s) from {cache_dir()}")
        return
    items = list_cache()
    _say(f"  {cache_dir()}: {len(items)} cached result(s), {sum(b for _, _, b in items) / 1e6:.1f} MB")
    for path, kind, size in items:
        _say(f"    {kind:8s} {size / 1e3:9.1f} kB  {path.name}")


# ----------------------------------------------------------------------------- argument types
def _number(text, kind=float):
    try:
        v = kind(text)
    except (TypeError, ValueError):
        raise argparse.ArgumentTypeError(f"{text!r} is not {'an integer' if kind is int else 'a number'}") from None
    if kind is float and math.isnan(v):
        raise argparse.ArgumentTypeError(f"{text!r} is not a number")
    return v


def positive(text):
    """a number > 0 (finite)"""
    v = _number(text)
    if not (math.isfinite(v) and v > 0):
        raise argparse.ArgumentTypeError(f"must be a finite number > 0, got {text!r}")
    return v


def non_negative(text):
    """a number >= 0 (finite)"""
    v = _number(text)
    if not (math.isfinite(v) and v >= 0):
        raise argparse.ArgumentTypeError(f"must be a finite number >= 0, got {text!r}")
    return v


def length_or_inf(text):
    """a length >= 0, mm, or inf"""
    v = _number(text)
    if not v >= 0:
        raise argparse.ArgumentTypeError(f"must be a length >= 0 (mm) or inf, got {text!r}")
    return v


def fraction(text):
    """a number in (0, 1)"""
    v = _number(text)
    if not 0 < v < 1:
        raise argparse.ArgumentTypeError(f"must lie strictly between 0 and 1 (0.3 = 30 %), got {text!r}")
    return v


def prestrain(text):
    """a number in [0, 1)"""
    v = _number(text)
    if not 0 <= v < 1:
        raise argparse.ArgumentTypeError(f"must lie in [0, 1) (0.3 = 30 %), got {text!r}")
    return v


def tensile_strain(text):
    """a number in (0, 2]"""
    v = _number(text)
    if not (math.isfinite(v) and 0 < v <= 2):
        raise argparse.ArgumentTypeError(f"must be a fraction > 0 and at most 2 (0.3 = 30 %), got {text!r}")
    return v


def count(text):
    """an integer >= 1"""
    v = _number(text, int)
    if v < 1:
        raise argparse.ArgumentTypeError(f"must be an integer >= 1, got {text!r}")
    return v


def seed(text):
    """an integer >= 0"""
    v = _number(text, int)
    if v < 0:
        raise argparse.ArgumentTypeError(f"must be an integer >= 0, got {text!r}")
    return v


# ----------------------------------------------------------------------------- the parser
class Parser(argparse.ArgumentParser):
    """argparse with a "did you mean" on a wrong option, choice or subcommand; errors print this
    (sub)command's own usage and exit with status 2."""

    def error(self, message):
        self.print_usage(sys.stderr)
        self.exit(2, f"{self.prog}: error: {message}{self._suggest(message)}\n")

    def _options(self) -> list:
        return [o for a in self._actions for o in a.option_strings]

    def _suggest(self, message) -> str:
        m = re.search(r"invalid choice: '([^']*)' \(choose from (.*)\)", message)
        if m:
            choices = re.findall(r"'([^']*)'", m.group(2)) or [c.strip() for c in m.group(2).split(",")]
            near = difflib.get_close_matches(m.group(1), choices, n=1, cutoff=0.5)
            return f"; did you mean {near[0]!r}?" if near else ""
        m = re.search(r"unrecognized arguments: (.*)", message)
        if m:
            hints = []
            opts = {o.lstrip("-"): o for o in self._options()}
            for word in m.group(1).split():
                if word.startswith("-"):
                    opt = word.split("=")[0]
                    near = difflib.get_close_matches(opt.lstrip("-"), list(opts), n=1, cutoff=0.6)
                    if near:
                        hints.append(f"{opt}: did you mean {opts[near[0]]}?")
            if hints:
                return f"; {' '.join(hints)} (see {self.prog} --help)"
            return f" (see {self.prog} --help)"
        return f" (see {self.prog} --help)" if " " in self.prog else ""


def _add_out(s, default: str) -> None:
    s.add_argument("--out", metavar="DIR", default=None,
                   help=f"output folder, created if missing; must be a writable folder, not a file "
                        f"(default: {default})")



def _add_macro(sub) -> None:
    s = sub.add_parser("macro", help="force-compression curve of a seamed specimen (cushion layer)",
                       description="Macro cushion layer: force over punch travel of a (seamed) specimen under "
                       "the 121 cm^2 plate, with a summary line (max force, force at 30 %, first contact): "
                       "<cell file stem>_macro_<noseam|d mm>.nc/.png.")
    s.add_argument("cell", metavar="CELL", help=CELL_HELP + "; a spacer cell (spacer_20mm)")
    s.add_argument("--distance", type=positive, default=None, metavar="D",
                   help="seam distance, mm, > 0 (default: no seams)")
    s.add_argument("--steps", type=count, default=None, metavar="N",
                   help="plate steps of the unseamed compression law, the large-motion engine's curve to 70 %% "
                        "with the cell file's friction, as macro_curve computes it (kept in the result cache), "
                        "integer >= 1 (default: 35)")
    s.add_argument("--curve", metavar="FILE.nc", default=None,
                   help="a stored compression law instead: the .nc file `homtex compress` writes (default: none, "
                        "computed with --steps)")
    s.add_argument("--strain", type=fraction, default=None, metavar="EPS",
                   help="final punch travel / thickness, a fraction in (0, 1) (default: 0.5; with --curve where the "
                        "curve ends, at most 0.5)")
    s.add_argument("--scatter", type=non_negative, default=0.0, metavar="MM",
                   help="standard deviation of the cushion-to-cushion height, mm, >= 0 (default: %(default)s)")
    s.add_argument("--seed", type=seed, default=0, metavar="N",
                   help="random seed of the height scatter, integer >= 0 (default: %(default)s)")
    s.add_argument("--pre-stress", choices=("thread", "held", "released"), default="thread",
                   help="who carries a pre-compressed cushion's pre-load under the punch: the thread hands it "
                        "over within its slack travel (thread), keeps it (held) or drops it at contact (released) "
                        "(default: %(default)s)")
    s.add_argument("--slack-travel", type=length_or_inf, default=None, metavar="MM",
                   help="thread slack travel, mm, >= 0 or inf (default: from the seam profile)")
    s.add_argument("--seam-method", choices=("yarn", "foundation"), default="yarn",
                   help="seam model that gives the cushion profile: yarn-level seam cell or the calibrated "
                        "foundation model (default: %(default)s)")
    s.add_argument("--law", choices=("columns", "cushion"), default="columns",
                   help="columns: every strip of the plate on the unseamed law from its own height (fast, no "
                        "sewing; 26-40 %% off yarn-level strips to 50 %%); cushion: every cushion on the sewn seam "
                        "cell's own yarn-level curve, shifted by its height (1.3 %% off; needs --distance; the first "
                        "call sews and presses, minutes, then cached) (default: %(default)s)")
    _add_out(s, "results/macro")
    s.set_defaults(func=cmd_macro)


def _add_tensile(sub) -> None:
    """The ``tensile`` subcommand (its own function: build_parser stays readable)."""
    s = sub.add_parser("tensile", help="tensile test of a weft-knit cell along the wales or the courses",
                       description="A weft-knit cell relaxed (homtex.relax: take-down 0.06 N per 5 needles, lattice "
                       "free in the fabric plane) and its periodic cell pulled along the wales or the courses with "
                       "free lateral contraction (homtex.tensile), as the API computes them: "
                       "<cell file stem>_tensile_<direction>.nc/.png (force per width, N/mm) and "
                       "<cell file stem>_tensile_<direction>_energy.png (energy split).")
    s.add_argument("cell", metavar="CELL", help=CELL_HELP + "; a weft-knit cell (jersey_eglass, rib_1x1_eglass, "
                   "milano_eglass, jersey_acrylic, rib_1x1_acrylic)")
    s.add_argument("--direction", choices=("wale", "course"), required=True,
                   help="test direction: wale (along the wales, the lattice vector a2) or course (along the "
                        "courses, a1) (required)")
    s.add_argument("--strain", type=tensile_strain, required=True, metavar="S",
                   help="final extension over the gauge length, a fraction > 0 and at most 2 (0.3 = 30 %%) "
                        "(required)")
    s.add_argument("--steps", type=count, default=None, metavar="N",
                   help="reported levels, integer >= 1; the engine halves a step that fails (default: one per "
                        "1 %% of strain, at least 10)")
    s.add_argument("--friction", type=non_negative, default=None, metavar="MU",
                   help="Coulomb coefficient (dimensionless) between the yarns, >= 0, in the relaxation and the "
                        "test (default: the cell file's [contact] friction, else 0)")
    _add_out(s, "results/tensile")
    s.set_defaults(func=cmd_tensile)

def build_parser() -> Parser:
    p = Parser(prog="homtex", description="homtex: yarn-level mechanics of technical textiles, one command per "
               "pipeline stage, each writing netCDF + PNG.",
               epilog="CELL is " + CELL_HELP + ". Run 'homtex <command> --help' for a command's arguments.")
    p.add_argument("--version", action="version", version=f"homtex {__version__}")
    p.add_argument("--debug", action="store_true",
                   help="show the full traceback of an error instead of a one-line message")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND", parser_class=Parser)

    s = sub.add_parser("run", help="the main job: the paper's study end to end on the engine (about 13 min "
                       "from a cold result cache on two cores)",
                       description="The main job on the large-motion engine: lattice demo, spacer cell, unseamed "
                       "compression to 70 %%, cushions sewn from the yarns (18, 24, 43 mm; low needle-thread "
                       "setting), the seamed 24 mm specimen to 70 %% against the macro layer, macro curves, a "
                       "strip of differing cushions against the macro layer, speed-accuracy; netCDF + PNG per "
                       "stage and summary.md. Sewn states and pressed curves are kept in the result cache "
                       "(homtex cache --help): a second run reads them.")
    _add_out(s, "results")
    s.add_argument("--quick", action="store_true",
                   help="every stage on seam cells of one to three fabric repeats, sewn frictionless in one "
                   "ramp level (about 1 min; checks the pipeline, not the paper's numbers; default: off)")
    s.add_argument("--workers", type=int, choices=(1, 2), default=None,
                   help="processes: with 2 the strip of seam cells is sewn and pressed in a second process "
                   "while the other stages run (default: 2 on a machine with two cores or more, else 1)")
    s.set_defaults(func=cmd_run)

    s = sub.add_parser("cell", help="summary and picture of a unit cell",
                       description="Summary (text), picture (PNG) and VTK (with meshio) of a cell: "
                       "<cell file stem>_cell.txt/.png/.vtu.")
    s.add_argument("cell", metavar="CELL", help=CELL_HELP)
    _add_out(s, "results/cell")
    s.set_defaults(func=cmd_cell)

    s = sub.add_parser("homogenize", help="effective stiffness of a periodic cell",
                       description="Effective stiffness C of a periodic cell and its engineering constants: "
                       "<cell file stem>_homogenized.nc/.png.")
    s.add_argument("cell", metavar="CELL", help=CELL_HELP)
    s.add_argument("--solver", default="amg", choices=["amg", "direct", "cg"],
                   help="linear solver: amg (AMG-preconditioned CG), direct (sparse LU) or cg (default: %(default)s)")
    _add_out(s, "results/homogenize")
    s.set_defaults(func=cmd_homogenize)

    s = sub.add_parser("compress", help="compression curve of a fabric cell between plates",
                       description="Yarn-level compression of a fabric cell between rigid plates (contact "
                       "yarn-yarn and yarn-plate), by default on the large-motion engine with the cell file's "
                       "friction, as homtex.compress: <cell file stem>_compression.nc/.png "
                       "(<cell file stem>_compression_linear.nc/.png with --geometry linear).")
    s.add_argument("cell", metavar="CELL", help=CELL_HELP)
    s.add_argument("--strain", type=fraction, default=0.3, metavar="EPS",
                   help="final compression = plate displacement / thickness, a fraction in (0, 1) (default: "
                        "%(default)s, i.e. 30 %%)")
    s.add_argument("--steps", type=count, default=20, metavar="N",
                   help="load steps, integer >= 1; the engine halves a step that fails, the linear model "
                        "re-linearises contact per step (default: %(default)s)")
    s.add_argument("--geometry", choices=("linear", "nonlinear"), default="nonlinear",
                   help="nonlinear: the large-motion engine (co-rotational beams, barrier contact, the cell "
                        "file's friction), to 70 %% and beyond, as homtex.compress by default; linear: the "
                        "small-rotation model, frictionless, valid only to the cell's [validity] "
                        "linear_strain_limit (a curve beyond it is flagged) (default: %(default)s)")
    s.add_argument("--friction", type=non_negative, default=None, metavar="MU",
                   help="Coulomb coefficient (dimensionless) of every yarn-yarn and yarn-plate contact, >= 0 "
                        "(the engine; not with --geometry linear; default: the cell file's [contact] table, else 0)")
    _add_out(s, "results/compress")
    s.set_defaults(func=cmd_compress)

    s = sub.add_parser("seam", help="cushion profile of a seam cell",
                       description="Cushion profile between parallel lock-stitch seams: "
                       "<cell file stem>_seam_<d>mm_<method>.nc/.png.")
    s.add_argument("cell", metavar="CELL", help=CELL_HELP + "; needs a [parameters.seam] table (spacer_20mm)")
    s.add_argument("--distance", type=positive, required=True, metavar="D",
                   help="seam distance, mm, > 0 (required; the yarn-level cell rounds it to whole fabric "
                        "repeats, e.g. 24 -> 25.4 mm)")
    s.add_argument("--prestrain", type=prestrain, default=None, metavar="EPS",
                   help="stitch-yarn pre-strain, a fraction in [0, 1) (default: the cell file's value for the "
                        "method: 0.3 yarn, 0.4 foundation for spacer_20mm)")
    s.add_argument("--method", choices=("yarn", "foundation"), default="yarn",
                   help="yarn: the yarn-level seam cell (blind, seconds to a minute); foundation: the analytical model "
                        "calibrated on d = 24 mm (fast) (default: %(default)s)")
    _add_out(s, "results/seam")
    s.set_defaults(func=cmd_seam)

    _add_macro(sub)
    _add_tensile(sub)

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

    s = sub.add_parser("plot", help="chart of a homtex netCDF file",
                       description="The chart of a netCDF file homtex wrote: the dedicated chart of its kind "
                       "(compression curve, seam profile, macro curve, study result, homogenisation, ...), else "
                       "one panel per unit.")
    s.add_argument("file", metavar="FILE.nc", help="a netCDF file written by homtex (path)")
    s.add_argument("--out", default=None, metavar="IMAGE",
                   help="image file to write; the format follows the extension (.png, .pdf, .svg, ...) "
                        "(default: FILE with .png)")
    s.add_argument("--var", default=None, metavar="NAME",
                   help="variable to draw (studies and generic charts; default: the first that fits)")
    s.add_argument("--sel", action="append", default=None, metavar="DIM=VALUE",
                   help="one value of a further dimension of --var, e.g. --sel row=11 --sel col=11 "
                        "(repeatable; default: none)")
    s.set_defaults(func=cmd_plot)
    s = sub.add_parser("cache", help="list or clear the result cache",
                       description="The result cache keeps cell computations (sewn seam cells, their profiles, "
                       "the unseamed law of macro_curve) in $HOMTEX_CACHE_DIR (default ~/.cache/homtex), keyed "
                       "by the cell's content, the parameters and the homtex version.")
    s.add_argument("--clear", action="store_true", help="remove every cached result (default: list them)")
    s.set_defaults(func=cmd_cache)
    for name, sp in sub.choices.items():   # --debug also after the command (homtex seam ... --debug)
        sp.add_argument("--debug", action="store_true", default=argparse.SUPPRESS,
                        help="show the full traceback of an error")
    p.commands = dict(sub.choices)
    return p


class _Console(logging.StreamHandler):
    """A handler writing to whatever sys.stdout is at the time (a progress bar's proxy, pytest's capture)."""

    @property
    def stream(self):
        return sys.stdout

    @stream.setter
    def stream(self, value):
        pass


def _log_to_console() -> logging.Handler:
    """INFO and above from the homtex loggers on stdout (what a long stage is doing)."""
    handler = _Console()
    handler.setFormatter(logging.Formatter("%(message)s"))
    log.addHandler(handler)
    log.setLevel(logging.INFO)
    return handler


#: a user's mistake: bad input (InputError), a failed solve (SolverError) or the system refusing
#: (a missing, unreadable or unwritable file or folder, a full disk, an unreachable scheduler)
USER_ERRORS = (InputError, SolverError, OSError)


def _message(exc: BaseException) -> str:
    if isinstance(exc, OSError) and not isinstance(exc, (InputError, SolverError)) and exc.strerror:
        where = f": {exc.filename}" if exc.filename else ""
        return f"{exc.strerror}{where}"
    return str(exc) or type(exc).__name__


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit status (0 ok, 1 a failed computation (raised as
    SystemExit(1)), 2 a user's mistake, 3 an internal error, 130 interrupted). An interrupt
    (Ctrl-C) anywhere, the stage modules' imports included, is one line and status 130."""
    command = None
    try:
        parser = build_parser()
        try:
            args, extra = parser.parse_known_args(argv)
            if extra:   # an unknown option belongs to the subcommand: its usage and a suggestion
                parser.commands[args.command].error(
                    f"unrecognized arguments: {' '.join(extra)}")
        except SystemExit as exc:   # --help, --version, a usage error (argparse printed it)
            return exc.code if isinstance(exc.code, int) else 2
        command = args.command
        out = getattr(args, "out", None)
        if out is not None and not str(out).strip():
            print(f"homtex {command}: error: --out {out!r}: an empty path; give a folder (or an image file for "
                  "plot), or leave --out out for the default", file=sys.stderr)
            return 2
        return _run(args)
    except KeyboardInterrupt:
        print(f"homtex{' ' + command if command else ''}: interrupted", file=sys.stderr)
        return 130


def _run(args) -> int:
    """Run the parsed command: its exit status, with one line for an error (see :func:`main`)."""
    handler = _log_to_console()
    try:
        args.func(args)
    except USER_ERRORS as exc:
        if args.debug:
            raise
        print(f"homtex {args.command}: error: {_message(exc)}", file=sys.stderr)
        return 2
    except Exception as exc:  # noqa: BLE001 - anything else is ours: one line, and how to report it
        if args.debug:
            raise
        print(f"homtex {args.command}: internal error ({type(exc).__name__}: {_message(exc)}); run it again with "
              f"--debug for the traceback and report it", file=sys.stderr)
        return 3
    finally:
        log.removeHandler(handler)
    return 0


if __name__ == "__main__":
    sys.exit(main())
