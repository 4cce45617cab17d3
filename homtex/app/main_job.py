"""The main job: the source paper's spacer-fabric study end to end (README's first command), on
the large-motion engine."""

from __future__ import annotations

import logging
import multiprocessing
import os
import time
from pathlib import Path

import numpy as np

from ..analysis.regions import three_regions
from ..cells import load_cell
from ..config import set_options
from ..macro import engine_law
from ..output.plot import plot_cell
from ..seams.strip import strip_yarn
from ..validate import check_int
from .paths import heartbeat
from .seam_stages import (
    CUSHION_HEADER,
    cushion_stage,
    macro_stage,
    seamed_stage,
    speed_accuracy_stage,
    strip_stage,
)
from .stages import SPACER_CELL, _markdown_table, _timed, lattice_demo, unseamed_stage

__all__ = ["main_job"]

log = logging.getLogger(__name__)

#: the paper's study (the full job) and its smaller version (``--quick``: seam cells of one to three
#: fabric repeats, sewn frictionless in one ramp level, pressed to 36 %: every stage in minutes;
#: it checks the pipeline, not the paper's numbers)
PLANS = {
    False: dict(strain=0.7, steps=35, distances=(18.0, 24.0, 43.0), seamed=24.0, lattice=(6, 6, 6),
                strip=dict(seam_distance=18.0, factors=(1.1, 0.9, 1.0), strain=0.5, steps=25), cell={}),
    True: dict(strain=0.36, steps=18, distances=(4.25, 8.5, 12.75), seamed=8.5, lattice=(3, 3, 3),
               strip=dict(seam_distance=4.25, factors=(1.1, 0.9, 1.0), strain=0.36, steps=18),
               cell={"contact.friction": 0.0, "contact.plate_friction": 0.0, "parameters.seam.prestrain": 0.3,
                     "parameters.seam.ramp_steps": 1}),
}


class _Background:
    """``fn(**kwargs)`` in one spawned process (a fresh interpreter: a fork of a process whose
    numba / BLAS thread pools already ran can hang), so a second core works while this process
    goes on; :meth:`result` waits for it, :meth:`close` stops it (an error in the main process
    must not leave it running for minutes)."""

    def __init__(self, fn, kwargs: dict):
        level = logging.getLogger("homtex").getEffectiveLevel()
        self._pool = multiprocessing.get_context("spawn").Pool(1, initializer=_child_setup, initargs=(level,))
        self._job = self._pool.apply_async(fn, kwds=kwargs)

    def result(self):
        try:
            return self._job.get()
        finally:
            self.close()

    def close(self) -> None:
        self._pool.terminate()
        self._pool.join()


def _child_setup(level: int) -> None:
    logging.basicConfig(level=max(level, logging.WARNING), format="[strip process] %(levelname)s %(name)s: %(message)s")
    set_options(threads=1)


def main_job(out: Path, *, quick: bool = False, workers: int | None = None) -> dict:
    """The README's main job: the paper's study end to end on the large-motion engine. Returns
    {description: path}.

    Stages: lattice demo (solver check) -> spacer cell picture -> unseamed compression to 70 % ->
    cushions sewn from the yarns (18, 24, 43 mm; the low needle-thread setting at 43 mm) beside the
    foundation model -> the seamed d = 24 mm specimen to 70 % (Fig. 11 of the paper) against the
    macro layer -> macro curves for every specimen -> a strip of differing cushions under one
    punch against the macro layer -> speed-accuracy chart; summary.md collects the tables and the
    stage times. Every sewn state and pressed curve is computed once and kept in the result cache
    (:mod:`homtex.cache`): a second run reads them.

    ``workers``: processes (default: 2 where the machine has two cores or more, else 1). With two,
    the strip's yarn-level sewing and press (the longest chain, independent of the other stages)
    run in a second process from the start, while this one computes the rest; the results are
    the same either way (each computation is deterministic and keyed in the cache).
    """
    workers = min(2, os.cpu_count() or 1) if workers is None else check_int(workers, "workers", ge=1, le=2)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    plan = PLANS[bool(quick)]
    outputs, times = {}, {}
    t0 = time.perf_counter()
    t_last = [t0]

    def stage(name, msg):
        now = time.perf_counter()
        times[name] = now - t_last[0]
        t_last[0] = now
        log.info("[%6.1f s] %s (%.1f s)", now - t0, msg, times[name])

    log.info("homtex main job (%s) into %s: 8 stages; a line at least every 10 s", "quick" if quick else "full", out)
    with heartbeat("lattice demo: octet block with amg, direct and cg"):
        outputs.update(lattice_demo(out, repeat=plan["lattice"]))
    stage("lattice demo", "lattice demo (amg, direct, cg on the same octet block) done")
    cell = load_cell(SPACER_CELL)
    outputs["spacer cell (picture)"] = plot_cell(cell, out / "spacer_cell.png",
                                                 title=f"{cell.name}: the unseamed spacer cell by yarn system")
    if plan["cell"]:
        cell = cell.replace(**plan["cell"])
    if workers == 1:
        return _stages(cell, out, plan, quick, outputs, stage, None, t0, times)
    # one thread per process: the engine's kernels hardly use a second one (a sewing runs at 98 %
    # of one core alone), and idle pool threads that spin would take the other process's core
    with set_options(threads=1):
        background = _Background(strip_yarn, dict(cell=cell, **plan["strip"]))
        try:
            return _stages(cell, out, plan, quick, outputs, stage, background, t0, times)
        finally:
            background.close()


def _stages(cell, out, plan, quick, outputs, stage, background, t0, times) -> dict:
    """The main job's stages after the spacer cell's picture (:func:`main_job`)."""
    # the macro layer's own law (cached), so the unseamed curve is computed once for both
    with heartbeat(f"unseamed compression to {100 * plan['strain']:g} % on the engine"):
        law, _ = _timed(engine_law, cell, strain=plan["strain"], steps=plan["steps"])
    curve, summ, paths = unseamed_stage(cell, out, strain=plan["strain"], geometry="nonlinear", curve=law)
    outputs.update(paths)
    stage("unseamed", f"unseamed compression: {curve.sizes['strain']} levels, status {curve.attrs['status']}")
    profiles, rows, paths = cushion_stage(cell, out, distances=plan["distances"])
    outputs.update(paths)
    stage("cushions", "cushions sewn on the engine (and the foundation model) done")
    given = law if quick else None       # the full job calls the macro layer exactly as a user does
    seamed, seam_summ, paths = seamed_stage(cell, curve, profiles, out, seam_distance=plan["seamed"],
                                            strain=plan["strain"], steps=plan["steps"],
                                            error_strain=min(0.5, plan["strain"]), curve=given)
    outputs.update(paths)
    stage("seamed", f"seamed d = {plan['seamed']:g} mm to {100 * plan['strain']:g} %: status "
          f"{seamed.attrs['yarn_status']}, macro {seam_summ['speedup']:.0f}x faster")
    macro, paths = macro_stage(cell, out, distances=plan["distances"], strain=plan["strain"], curve=given)
    outputs.update(paths)
    stage("macro", "macro curves done")
    # the strip's calibrated seam is the seamed stage's cell, pressed there on the same 2 % levels
    same = plan["strip"]["seam_distance"] == plan["seamed"]
    strip, paths = strip_stage(cell, out, curve=given, singles={1.0: seam_summ["yarn"]} if same else None,
                               background=background, **plan["strip"])
    outputs.update(paths)
    stage("strip", f"strip of {strip.attrs['seams']} seam cells: status {strip.attrs.get('status', 'ok')}")
    sa, paths = speed_accuracy_stage(cell, curve, seam_summ, strip, out, quick=quick)
    outputs.update(paths)
    stage("speed-accuracy", "speed-accuracy chart done")
    summary = out / "summary.md"
    summary.write_text(_summary(quick, time.perf_counter() - t0, times, rows, curve, seamed, seam_summ, macro,
                                strip, sa))
    outputs["summary tables (markdown)"] = summary
    log.info("done in %.0f s; tables in %s", time.perf_counter() - t0, summary)
    return outputs


def _regions_row(name, ds) -> tuple:
    e, s = ds.strain.values, ds.stress.values
    r = three_regions(e, s, start=float(e[np.argmax(s > 0.05 * s.max())]) if (s > 0).any() else 0.0)
    b, k = r["breaks"], r["slopes"]
    return (name, f"{100 * b[0]:.0f} / {100 * b[1]:.0f} %", " / ".join(f"{v:.0f}" for v in k),
            f"{s[-1]:.2f}", f"{float(ds.force.values[-1]) if 'force' in ds else np.nan:.2f}",
            f"{s[-1] * 12.1:.0f}", ds.attrs.get("status", "ok"))


def _summary(quick, seconds, times, rows, curve, seamed, seam_summ, macro, strip, sa) -> str:
    md = [f"# homtex main job ({'quick' if quick else 'full'}), {seconds:.0f} s", ""]
    if quick:
        md += ["Quick run: seam cells of one to three fabric repeats, sewn frictionless in one ramp level with "
               "eps0 = 0.3, pressed to 36 %; it checks the pipeline, not the paper's numbers.", ""]
    md += ["## Stage times", "", _markdown_table(["stage", "s"], [(k, f"{v:.1f}") for k, v in times.items()]), ""]
    if strip.attrs.get("strip_process", "").startswith("second"):
        md += [f"The strip was sewn and pressed at yarn level ({float(strip.attrs['seconds_strip']):.0f} s) in a "
               "second process from the job's start; the strip stage's time above is its single cells' presses and the "
               "wait for it.", ""]
    md += ["## Cushion heights", "",
           "yarn: the seam sewn on the large-motion engine (lock stitch 301, friction of the cell file), its "
           "stitch calibrated once on d = 24 mm (the paper's needle-thread setting 40 %); 18 and 43 mm and the "
           "low setting (15 %, mapped in proportion) are predictions. foundation: the analytical seam model, "
           "layer rigidity calibrated on 24 mm.", "", _markdown_table(CUSHION_HEADER, rows), ""]
    e_s = float(seamed.attrs["end_strain"])
    md += ["## Compression to the end of the stroke (yarn level, engine)", "",
           "Three regions: a continuous three-segment fit of stress over strain (slow rise, near-linear rise, "
           "stiffening; homtex.analysis.regions.three_regions); the paper's curves exist only as plots, so "
           "no agreement with them is claimed. Force on the test's 121 cm^2 plate (500 N load cell).", "",
           _markdown_table(["specimen", "slope changes at", "slopes, kPa per unit strain",
                            f"stress at {100 * e_s:.0f} %, kPa", "force on the cell, N", "force on 121 cm^2, N",
                            "status"],
                           [_regions_row("no seams", curve), _regions_row(
                               f"d = {seamed.attrs['seam_distance_mm']:g} mm", seam_summ["yarn"])]), ""]
    if seamed.attrs.get("yarn_status", "ok") != "ok":
        md += [f"The seamed curve is **{seamed.attrs['yarn_status']}**: {seamed.attrs['yarn_status_detail']}", ""]
    md += [f"## Seamed d = {seamed.attrs['seam_distance_mm']:g} mm: macro layer against the yarn level", "",
           _markdown_table(["macro layer fed", f"max error to {100 * min(0.5, e_s):.0f} %",
                            f"to {100 * e_s:.0f} %", "macro, ms", "yarn level (sewing + press), s", "speed-up"],
                           [(what, f"{100 * seamed.attrs[f'max_relative_error_{k}_to_error_strain']:.1f} %",
                             f"{100 * seamed.attrs[f'max_relative_error_{k}_to_end']:.1f} %",
                             f"{1e3 * seamed.attrs[sk]:.2f}", f"{seamed.attrs['yarn_seconds']:.0f}",
                             f"{seamed.attrs['yarn_seconds'] / seamed.attrs[sk]:.0f}x")
                            for what, k, sk in (("the engine's cushion", "macro", "macro_seconds"),
                                                ("the foundation model's cushion", "macro_foundation",
                                                 "foundation_macro_seconds"))]), ""]
    e_c = 100 * float(strip.strain[-1])
    md += [f"## Strip of {strip.attrs['seams']} differing cushions under one punch against the macro layer", "",
           f"cushions {' / '.join(f'{h:.2f}' for h in strip.cushion_height_strip.values)} mm; force error = max "
           f"difference over the curve / the strip's stress at {e_c:.0f} % "
           f"({strip.attrs['reference_stress_kPa']:.2f} kPa); strip sewn and pressed in "
           f"{strip.attrs['seconds_strip']:.0f} s; status {strip.attrs.get('status', 'ok')}", "",
           _markdown_table(["prediction", "error", "run time, s"],
                           [(k, f"{100 * strip.attrs[f'error_{k}']:.1f} %", f"{strip.attrs[f'seconds_{k}']:.2g}")
                            for k in ("shifted_law", "cushion_laws", "columns")]), ""]
    w = macro.plate_displacement.values
    mrows = []
    for sp in macro.specimen.values:
        F = np.nan_to_num(macro.force.sel(specimen=sp).values)
        reach = w[F >= 50.0]
        mrows.append((str(sp), f"{reach[0]:.2f}" if reach.size else "-", f"{np.interp(4.0, w, F):.1f}",
                      f"{F.max():.1f}"))
    md += ["## Macro curves (121 cm^2 plate, 1 mm cushion scatter)", "",
           _markdown_table(["specimen", "travel to 50 N, mm", "force at 4 mm, N", "max force, N"], mrows),
           "", f"status: {macro.attrs['status']}", ""]
    md += ["## Speed against accuracy", "",
           _markdown_table(["question", "model", "run time, s", "error"],
                           [(str(q), str(m), f"{t:.3g}", f"{e:.2e}") for q, m, t, e in
                            zip(sa.question.values, sa.model.values, sa.seconds.values, sa.error.values)]), ""]
    return "\n".join(md)
