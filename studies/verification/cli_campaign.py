"""Command-line campaign: every user mistake we could think of, run through the real ``homtex``
command (a subprocess each), counting clean errors (exit 2, one ``homtex <cmd>: error:`` line,
no traceback), tracebacks and internal errors (exit 3). A few correct invocations with hostile
inputs (a cell named ``../outside/escaped``) check that the guards do not refuse good work and
that nothing is written outside ``--out``.

Usage: python studies/verification/cli_campaign.py [--out DIR] [--quick]
       (default results/cli_campaign/; --quick: one invocation in twenty, under half a minute)

Writes DIR/cli_campaign.nc (one row per invocation: command, expectation, exit status,
outcome, seconds, the last line of stderr) and DIR/cli_campaign.png (outcomes per subcommand),
prints the tally and every failure; exits 1 if any invocation was not clean.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import xarray as xr

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))   # this checkout's homtex, whatever is installed
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _common import parser, pyplot, save_figure, save_netcdf, setup  # noqa: E402

ERR, OK = "error", "ok"
#: a shipped study file (studies/configs/ on newer trees)
SQUARE = next((p for p in (ROOT / "studies" / "configs" / "square_stiffness.toml",
                           ROOT / "studies" / "square_stiffness.toml") if p.exists()),
              ROOT / "studies" / "square_stiffness.toml")


def _read_only_folder(tmp: Path) -> Path:
    """A folder this process cannot write to: a 0500 folder, or /sys for root."""
    from homtex.app.paths import writable

    ro = tmp / "read_only"
    ro.mkdir()
    ro.chmod(0o500)
    if not writable(ro):
        return ro
    if Path("/sys").is_dir() and not writable(Path("/sys")):
        return Path("/sys")
    raise SystemExit("no read-only folder for this user here (root on a writable /sys?)")


def _fixtures(tmp: Path) -> dict:
    """Files and folders the mistakes are made with."""
    from homtex.output.io import write_netcdf

    f = {"tmp": tmp, "folder": tmp / "a_folder", "file": tmp / "a_file.txt", "ro": _read_only_folder(tmp)}
    f["folder"].mkdir()
    f["file"].write_text("I am a text file\n")
    (tmp / "bad.toml").write_text("[cell\nname = 'x'\n")
    (tmp / "empty.toml").write_text("")
    (tmp / "binary.toml").write_bytes(bytes(range(256)) * 4)
    square = (ROOT / "cells" / "square.toml").read_text()
    (tmp / "unknown_generator.toml").write_text(square.replace('generator = "square"', 'generator = "pentagon"'))
    (tmp / "negative_radius.toml").write_text(square.replace("radius = 0.05", "radius = -0.05"))
    (tmp / "string_modulus.toml").write_text(square.replace("E = 3000.0", 'E = "stiff"'))
    (tmp / "evil_relative.toml").write_text(square.replace('name = "square"', 'name = "../outside/escaped"'))
    (tmp / "evil_absolute.toml").write_text(square.replace('name = "square"', f'name = "{tmp}/abs/escaped"'))
    (tmp / "bad_study.toml").write_text("[study\nname=1\n")
    (tmp / "study_missing_cell.toml").write_text('[study]\nname = "s"\ncell = "nope.toml"\ntask = "homogenize"\n'
                                                 '[parameters]\n"yarns.strut.E" = [1.0, 2.0]\n')
    e = np.linspace(0.0, 0.5, 11)
    law = xr.Dataset({"stress": ("strain", 100 * e, {"units": "kPa", "long_name": "stress"})},
                     coords={"strain": ("strain", e, {"units": "1", "long_name": "strain"})},
                     attrs={"thickness_mm": 20.0, "status": "ok"})
    f["law"] = write_netcdf(law, tmp / "law.nc")
    f["other"] = write_netcdf(xr.Dataset({"t": ("x", np.arange(3.0), {"units": "s", "long_name": "t"})}),
                              tmp / "not_a_curve.nc")
    f["scalars"] = write_netcdf(xr.Dataset({"a": ((), 1.0, {"units": "1", "long_name": "a"})}), tmp / "scalars.nc")
    E, r = np.array([1.0, 2.0]), np.array([0.1, 0.2])
    study = xr.Dataset({"C": (("E", "r", "row"), np.ones((2, 2, 2)), {"units": "N/mm", "long_name": "C"})},
                       coords={"E": ("E", E, {"units": "MPa", "long_name": "E"}),
                               "r": ("r", r, {"units": "mm", "long_name": "r"}), "row": ["11", "22"]},
                       attrs={"study_layout": "grid", "study_parameters": '["E", "r"]'})
    f["study"] = write_netcdf(study, tmp / "study.nc")
    (tmp / "empty.nc").write_bytes(b"")
    (tmp / "truncated.nc").write_bytes(f["law"].read_bytes()[:300])
    (tmp / "picture.png").write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(100))
    return f


def invocations(f: dict) -> list:
    """(label, argv, expected) for every mistake (expected "error") and a few hostile but correct runs."""
    t, d, x, ro, law = f["tmp"], f["folder"], f["file"], f["ro"], f["law"]
    out = str(t / "out")
    cl = ("--curve", law)
    return [
        ("no command", [], ERR), ("unknown command", ["frobnicate"], ERR), ("misspelt command", ["sem"], ERR),
        ("unknown top-level option", ["--bogus"], ERR), ("--debug alone", ["--debug"], ERR),
        ("run: --out is a file", ["run", "--out", x], ERR), ("run: --out read-only", ["run", "--out", ro], ERR),
        ("run: --out below a file", ["run", "--out", x / "sub"], ERR), ("run: misspelt option", ["run", "--quik"], ERR),
        ("run: stray argument", ["run", "foo"], ERR),
        ("cell: missing CELL", ["cell"], ERR), ("cell: unknown name", ["cell", "nosuch"], ERR),
        ("cell: misspelt name", ["cell", "spacer_20m"], ERR), ("cell: a folder", ["cell", d], ERR),
        ("cell: a text file", ["cell", x], ERR), ("cell: malformed TOML", ["cell", t / "bad.toml"], ERR),
        ("cell: empty file", ["cell", t / "empty.toml"], ERR), ("cell: binary file", ["cell", t / "binary.toml"], ERR),
        ("cell: unknown generator", ["cell", t / "unknown_generator.toml"], ERR),
        ("cell: negative radius", ["cell", t / "negative_radius.toml"], ERR),
        ("cell: modulus a string", ["cell", t / "string_modulus.toml"], ERR),
        ("cell: empty name", ["cell", ""], ERR), ("cell: --out is a file", ["cell", "square", "--out", x], ERR),
        ("cell: --out read-only", ["cell", "square", "--out", ro], ERR),
        ("homogenize: unknown solver", ["homogenize", "square", "--solver", "foo"], ERR),
        ("homogenize: misspelt solver", ["homogenize", "square", "--solver", "amgg"], ERR),
        ("homogenize: unknown option", ["homogenize", "square", "--tol", "1e-8"], ERR),
        ("homogenize: unknown cell", ["homogenize", "nosuch"], ERR),
        ("homogenize: --out is a file", ["homogenize", "square", "--out", x], ERR),
        ("compress: strain 1.5", ["compress", "spacer_20mm", "--strain", "1.5"], ERR),
        ("compress: strain 0", ["compress", "spacer_20mm", "--strain", "0"], ERR),
        ("compress: strain -0.1", ["compress", "spacer_20mm", "--strain", "-0.1"], ERR),
        ("compress: strain text", ["compress", "spacer_20mm", "--strain", "abc"], ERR),
        ("compress: strain nan", ["compress", "spacer_20mm", "--strain", "nan"], ERR),
        ("compress: strain inf", ["compress", "spacer_20mm", "--strain", "inf"], ERR),
        ("compress: strain as percent", ["compress", "spacer_20mm", "--strain", "30%"], ERR),
        ("compress: steps 0", ["compress", "spacer_20mm", "--steps", "0"], ERR),
        ("compress: steps -3", ["compress", "spacer_20mm", "--steps", "-3"], ERR),
        ("compress: steps 2.5", ["compress", "spacer_20mm", "--steps", "2.5"], ERR),
        ("compress: steps text", ["compress", "spacer_20mm", "--steps", "many"], ERR),
        ("compress: strain without value", ["compress", "spacer_20mm", "--strain"], ERR),
        ("compress: a cell that is no fabric", ["compress", "octet", "--strain", "0.05", "--steps", "1",
                                                "--out", out], ERR),
        ("compress: unknown cell", ["compress", "nosuch"], ERR),
        ("compress: misspelt option", ["compress", "spacer_20mm", "--stran", "0.2"], ERR),
        ("compress: --out read-only", ["compress", "spacer_20mm", "--out", ro], ERR),
        ("seam: missing --distance", ["seam", "spacer_20mm"], ERR),
        ("seam: distance 0", ["seam", "spacer_20mm", "--distance", "0"], ERR),
        ("seam: distance -24", ["seam", "spacer_20mm", "--distance", "-24"], ERR),
        ("seam: distance text", ["seam", "spacer_20mm", "--distance", "abc"], ERR),
        ("seam: distance inf", ["seam", "spacer_20mm", "--distance", "inf"], ERR),
        ("seam: distance with unit", ["seam", "spacer_20mm", "--distance", "24mm"], ERR),
        ("seam: prestrain 1.2", ["seam", "spacer_20mm", "--distance", "24", "--prestrain", "1.2"], ERR),
        ("seam: prestrain -0.1", ["seam", "spacer_20mm", "--distance", "24", "--prestrain", "-0.1"], ERR),
        ("seam: unknown method", ["seam", "spacer_20mm", "--distance", "24", "--method", "fem"], ERR),
        ("seam: cell without seam table", ["seam", "square", "--distance", "24", "--out", out], ERR),
        ("seam: foundation, prestrain too high", ["seam", "spacer_20mm", "--distance", "24", "--method", "foundation",
                                                  "--prestrain", "0.99", "--out", out], ERR),
        ("seam: yarn, distance below one repeat", ["seam", "spacer_20mm", "--distance", "0.5", "--out", out], ERR),
        ("seam: --out is a file", ["seam", "spacer_20mm", "--distance", "24", "--out", x], ERR),
        ("macro: steps 0", ["macro", "spacer_20mm", "--steps", "0"], ERR),
        ("macro: steps text", ["macro", "spacer_20mm", "--steps", "x"], ERR),
        ("macro: curve missing", ["macro", "spacer_20mm", "--curve", t / "missing.nc"], ERR),
        ("macro: curve a text file", ["macro", "spacer_20mm", "--curve", x], ERR),
        ("macro: curve a folder", ["macro", "spacer_20mm", "--curve", d], ERR),
        ("macro: curve not a curve", ["macro", "spacer_20mm", "--curve", f["other"]], ERR),
        ("macro: curve and steps", ["macro", "spacer_20mm", *cl, "--steps", "5"], ERR),
        ("macro: scatter -1", ["macro", "spacer_20mm", *cl, "--scatter", "-1"], ERR),
        ("macro: seed -1", ["macro", "spacer_20mm", *cl, "--seed", "-1"], ERR),
        ("macro: unknown pre-stress law", ["macro", "spacer_20mm", *cl, "--pre-stress", "maybe"], ERR),
        ("macro: slack travel -1", ["macro", "spacer_20mm", *cl, "--slack-travel", "-1"], ERR),
        ("macro: strain 1", ["macro", "spacer_20mm", *cl, "--strain", "1"], ERR),
        ("macro: distance 0", ["macro", "spacer_20mm", *cl, "--distance", "0"], ERR),
        ("macro: cell without seam table", ["macro", "square", *cl, "--distance", "24", "--out", out], ERR),
        ("macro: --out read-only", ["macro", "spacer_20mm", *cl, "--out", ro], ERR),
        ("study: missing file", ["study"], ERR),
        ("study: missing --out", ["study", SQUARE], ERR),
        ("study: a folder as study file", ["study", d, "--out", out], ERR),
        ("study: no such file", ["study", t / "missing.toml", "--out", out], ERR),
        ("study: a text file", ["study", x, "--out", out], ERR),
        ("study: malformed TOML", ["study", t / "bad_study.toml", "--out", out], ERR),
        ("study: its cell missing", ["study", t / "study_missing_cell.toml", "--out", out], ERR),
        ("study: --out is a file", ["study", SQUARE, "--out", x], ERR),
        ("study: --out read-only", ["study", SQUARE, "--out", ro], ERR),
        ("study: unreachable scheduler", ["study", SQUARE, "--out", t / "st1",
                                          "--scheduler", "tcp://127.0.0.1:9"], ERR),
        ("study: scheduler not an address", ["study", SQUARE, "--out", t / "st2",
                                             "--scheduler", "not an address"], ERR),
        ("plot: missing FILE", ["plot"], ERR), ("plot: no such file", ["plot", t / "missing.nc"], ERR),
        ("plot: a text file", ["plot", x], ERR), ("plot: a folder", ["plot", d], ERR),
        ("plot: empty file", ["plot", t / "empty.nc"], ERR),
        ("plot: truncated netCDF", ["plot", t / "truncated.nc"], ERR),
        ("plot: a PNG", ["plot", t / "picture.png"], ERR),
        ("plot: a cell file", ["plot", ROOT / "cells/square.toml"], ERR),
        ("plot: unknown extension", ["plot", law, "--out", t / "chart.xyz"], ERR),
        ("plot: no extension", ["plot", law, "--out", t / "chart"], ERR),
        ("plot: .nc as image", ["plot", law, "--out", t / "copy.nc"], ERR),
        ("plot: --out a folder", ["plot", law, "--out", d], ERR),
        ("plot: --out in a read-only folder", ["plot", law, "--out", ro / "chart.png"], ERR),
        ("plot: --out in a missing folder", ["plot", law, "--out", t / "nofolder" / "chart.png"], ERR),
        ("plot: unknown variable", ["plot", f["study"], "--var", "nope"], ERR),
        ("plot: variable needs --sel", ["plot", f["study"], "--var", "C"], ERR),
        ("plot: --sel unknown value", ["plot", f["study"], "--var", "C", "--sel", "row=33"], ERR),
        ("plot: --sel without =", ["plot", f["study"], "--var", "C", "--sel", "row"], ERR),
        ("plot: --sel unknown dimension", ["plot", f["study"], "--var", "C", "--sel", "col=11"], ERR),
        ("plot: nothing to draw", ["plot", f["scalars"]], ERR),
        ("plot: generic, unknown variable", ["plot", f["other"], "--var", "nope", "--out", t / "o.png"], ERR),
        # hostile but correct: must succeed and write only inside --out
        ("cell named ../outside/escaped", ["cell", t / "evil_relative.toml", "--out", t / "evil_out"], OK),
        ("cell named by an absolute path", ["cell", t / "evil_absolute.toml", "--out", t / "evil_out"], OK),
        ("homogenize a cell named ../outside", ["homogenize", t / "evil_relative.toml", "--out", t / "evil_out"], OK),
        ("plot a stored curve to SVG", ["plot", law, "--out", t / "law.svg"], OK),
        ("macro on a stored curve", ["macro", "spacer_20mm", *cl, "--out", t / "macro_out"], OK),
        ("plot a study's variable", ["plot", f["study"], "--var", "C", "--sel", "row=22", "--out", t / "s.png"], OK),
    ]


def classify(expected: str, rc: int, text: str) -> str:
    if "Traceback (most recent call last)" in text:
        return "traceback"
    if rc == 3:
        return "internal error"
    if rc in (124, -9):
        return "timeout"
    if expected == OK:
        return "ok" if rc == 0 else "refused a correct run"
    if rc == 2 and "error:" in text:
        return "clean error"
    return f"unexpected exit {rc}"


def run(argv, timeout=120):
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    t0 = time.perf_counter()
    try:
        p = subprocess.run([sys.executable, "-m", "homtex.app.cli", *map(str, argv)], capture_output=True,
                           text=True, timeout=timeout, cwd=ROOT, env=env)
        rc, text, err = p.returncode, p.stdout + p.stderr, p.stderr
    except subprocess.TimeoutExpired:
        rc, text, err = 124, "", "timeout"
    lines = [ln for ln in err.strip().splitlines() if ln.strip()]
    return rc, text, (lines[-1] if lines else "")[:400], time.perf_counter() - t0


def chart(ds, path):
    """Outcomes per subcommand, stacked bars."""
    plt = pyplot()
    sub = np.array([c.split()[1] if len(c.split()) > 1 else "(none)" for c in ds.command.values])
    names = sorted(set(sub))
    fig, ax = plt.subplots(figsize=(8, 4.5), layout="constrained")
    bottom = np.zeros(len(names))
    colours = {"clean error": "tab:green", "ok": "tab:blue", "traceback": "tab:red", "internal error": "tab:orange"}
    for outcome in sorted(set(ds.outcome.values)):
        n = np.array([np.sum((sub == s) & (ds.outcome.values == outcome)) for s in names])
        ax.bar(names, n, bottom=bottom, label=outcome, color=colours.get(outcome, "tab:gray"))
        bottom += n
    ax.set_xlabel("homtex subcommand")
    ax.set_ylabel("invocations (count)")
    ax.set_title(f"homtex command-line campaign: {int(ds.attrs['invocations'])} invocations, "
                 f"{int(ds.attrs['tracebacks'])} tracebacks")
    ax.legend(title="outcome")
    ax.tick_params(axis="x", rotation=30)
    return save_figure(fig, path)


def main(argv=None):
    args = parser(__file__, __doc__).parse_args(argv)
    quick = args.quick
    outdir = setup(args)
    rows = []
    with tempfile.TemporaryDirectory(prefix="homtex-cli-campaign-") as tmpname:
        tmp = Path(tmpname)
        cases = invocations(_fixtures(tmp))
        if quick:
            cases = cases[::20]
        for i, (label, cmd, expected) in enumerate(cases):
            rc, text, last, sec = run(cmd)
            outcome = classify(expected, rc, text)
            rows.append((label, "homtex " + " ".join(str(c).replace(tmpname, "$TMP") for c in cmd), expected, rc,
                         outcome, sec, last.replace(tmpname, "$TMP")))
            print(f"{i + 1:3d} {outcome:<22s} rc={rc:<3d} {sec:5.1f} s  {label}: {last.replace(tmpname, '$TMP')[:110]}",
                  flush=True)
        escaped = [str(p) for p in (tmp / "outside", tmp / "abs", tmp.parent / "outside") if p.exists()]
        (tmp / "read_only").chmod(0o700)
    ds = xr.Dataset(
        {"label": ("invocation", [r[0] for r in rows], {"units": "1", "long_name": "what the mistake is"}),
         "command": ("invocation", [r[1] for r in rows], {"units": "1", "long_name": "command line ($TMP: fixtures)"}),
         "expected": ("invocation", [r[2] for r in rows], {"units": "1", "long_name": "error or ok"}),
         "exit_status": ("invocation", np.array([r[3] for r in rows]), {"units": "1", "long_name": "exit status"}),
         "outcome": ("invocation", [r[4] for r in rows], {"units": "1", "long_name": "classified outcome"}),
         "seconds": ("invocation", np.array([r[5] for r in rows]), {"units": "s", "long_name": "wall time"}),
         "message": ("invocation", [r[6] for r in rows], {"units": "1", "long_name": "last line of stderr"})},
        coords={"invocation": ("invocation", np.arange(len(rows)), {"units": "1", "long_name": "invocation"})})
    tally = {o: sum(r[4] == o for r in rows) for o in sorted({r[4] for r in rows})}
    ds.attrs.update(title="homtex command-line campaign", quick=int(quick), invocations=len(rows),
                    tracebacks=tally.get("traceback", 0), internal_errors=tally.get("internal error", 0),
                    clean_errors=tally.get("clean error", 0), escaped_files=", ".join(escaped) or "none",
                    **{f"outcome_{k.replace(' ', '_')}": v for k, v in tally.items()})
    path = save_netcdf(ds, outdir / "cli_campaign.nc")
    chart(ds, outdir / "cli_campaign.png")
    print(f"\n{len(rows)} invocations: " + ", ".join(f"{v} {k}" for k, v in tally.items())
          + f"; files outside --out: {ds.attrs['escaped_files']}")
    bad = [r for r in rows if r[4] not in ("clean error", "ok")]
    for r in bad:
        print(f"  NOT CLEAN: {r[0]} -> {r[4]} (exit {r[3]}): {r[6]}")
    print(f"wrote {path}")
    return 1 if bad or escaped else 0


if __name__ == "__main__":
    sys.exit(main())
