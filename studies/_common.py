"""The command line every study script shares: ``--quick``, ``--out DIR``, console output, saving.

A script imports it with (its own folder is on ``sys.path``, the ``studies/`` folder is not)::

    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from _common import ROOT, parser, save_figure, save_netcdf, setup  # noqa: E402

``parser(__file__, __doc__)`` gives an argparse parser with ``--quick`` (a tiny version of the same
computation, seconds, for tests/test_studies.py) and ``--out DIR`` (default
``results/<script name>``); ``setup(args)`` checks the output folder, creates it, routes the
package's log messages to the console and returns it. Quick runs refuse to write into ``docs/``:
the charts there come from full runs.
"""

from __future__ import annotations

import argparse
import logging
import time
import warnings
from pathlib import Path

import homtex

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"

log = logging.getLogger("studies")


def parser(file: str, doc: str | None, **kw) -> argparse.ArgumentParser:
    """An argparse parser with the shared options ``--quick`` and ``--out``."""
    name = Path(file).stem
    try:
        prog = f"python {Path(file).resolve().relative_to(ROOT)}"
    except ValueError:          # a copy of the script outside the checkout
        prog = f"python {file}"
    p = argparse.ArgumentParser(prog=prog, description=doc, formatter_class=argparse.RawDescriptionHelpFormatter, **kw)
    p.add_argument("--quick", action="store_true",
                   help="a tiny version of the same computation (seconds; what tests/test_studies.py runs)")
    p.add_argument("--out", type=Path, default=Path("results") / name,
                   help=f"output folder for the netCDF file(s) and the chart (default results/{name})")
    return p


def add_docs_option(p: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """``--no-docs``: a full run does not copy its charts to docs/studies/ (see :func:`publish`)."""
    p.add_argument("--no-docs", action="store_true", help="do not copy the charts to docs/studies/")
    return p


def publish(args, *charts) -> None:
    """Copy the charts of a full run into docs/studies/ (not with --quick or --no-docs)."""
    import shutil

    if getattr(args, "quick", False) or getattr(args, "no_docs", False):
        return
    (DOCS / "studies").mkdir(exist_ok=True)
    for c in charts:
        shutil.copy(c, DOCS / "studies" / Path(c).name)


def setup(args, *, quiet_warnings: bool = True) -> Path:
    """Check and create ``args.out``, show the package's log messages; returns the folder.

    ``quiet_warnings``: Python warnings (cell-creation overlaps, which the cell reports itself)
    are ignored, as the studies always did.
    """
    out = Path(args.out)
    if getattr(args, "quick", False):
        res = out.resolve()
        if res == DOCS or DOCS in res.parents:
            raise SystemExit(f"--quick does not write into {DOCS}: the charts there come from full runs")
    out.mkdir(parents=True, exist_ok=True)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    logging.getLogger("numba").setLevel(logging.WARNING)
    if quiet_warnings:
        warnings.simplefilter("ignore")
    return out


def save_netcdf(ds, path) -> Path:
    """Write ``ds`` with :func:`homtex.output.io.write_netcdf` (atomic, strings and booleans handled)."""
    from homtex.output.io import write_netcdf

    return write_netcdf(ds, path)


def save_figure(fig, path, dpi: int = 120) -> Path:
    """Save a matplotlib figure and close it."""
    import matplotlib.pyplot as plt

    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    return Path(path)


def pyplot():
    """matplotlib.pyplot with the non-interactive Agg backend."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def relaxed_yarn_model(name: str, model: str, filaments: int, element: float | None = None):
    """(RelaxedCell, process CPU seconds): the shipped knit cell ``name`` with its yarn built as
    ``model`` ("filaments" or "equivalent") of ``filaments`` filaments (at ``element`` mm elements if
    given), relaxed with ``homtex.relax``."""
    changes = {"parameters.yarn_model.filaments": filaments, "parameters.yarn_model.model": model}
    if element is not None:
        changes["resolution.element_length"] = element
    cell = homtex.load_cell(name).replace(**changes)
    t0 = time.process_time()
    relaxed = homtex.relax(cell, cache=False)
    return relaxed, time.process_time() - t0
