"""Where the command line writes: output folders checked before any computing, output names
derived from the cell FILE's name and sanitised (a cell's ``name`` field never becomes a path),
and a heartbeat for long stages."""

from __future__ import annotations

import logging
import os
import re
import tempfile
import threading
import time
from contextlib import contextmanager
from pathlib import Path

from ..errors import InputError

__all__ = ["check_image_path", "heartbeat", "output_folder", "safe_stem", "stem_of", "writable", "write_problem"]

log = logging.getLogger("homtex.app")

_UNSAFE = re.compile(r"[^A-Za-z0-9._+-]+")


def safe_stem(text, *, default: str = "cell") -> str:
    """A file-name stem from ``text``: letters, digits, '.', '_', '+', '-' only (anything else,
    path separators included, becomes '_'), no leading dots (no '..', no hidden files), at most
    80 characters; ``default`` if nothing is left."""
    s = _UNSAFE.sub("_", str(text)).lstrip(".")
    s = s.strip("_") or default
    return s[:80]


def stem_of(cell) -> str:
    """Output-name stem of a cell: its file's stem (``cells/spacer_20mm.toml`` -> ``spacer_20mm``),
    sanitised; a cell without a file (built in Python) falls back to its sanitised name."""
    path = getattr(cell, "path", None)
    return safe_stem(Path(str(path)).stem if path else getattr(cell, "name", "cell"))


def write_problem(folder) -> OSError | None:
    """None if this process can create a file in ``folder`` (tried: os.access says yes to root
    everywhere), else the OSError the attempt raised."""
    try:
        fd, probe = tempfile.mkstemp(prefix=".homtex-write-test.", dir=folder)
    except OSError as exc:
        return exc
    os.close(fd)
    os.unlink(probe)
    return None


def writable(folder) -> bool:
    """Can this process create a file in ``folder``?"""
    return write_problem(folder) is None


def _not_writable(what, folder, exc: OSError) -> InputError:
    """InputError naming why ``folder`` takes no file: permission, read-only, full (from the
    error number first, :func:`homtex.output.io.write_failure`)."""
    from ..output.io import write_failure

    kind, cause = write_failure(folder, exc)
    if kind == "refused":
        return InputError(f"{what}: the folder is not writable ({cause}); make it writable or give another folder")
    if kind == "full":
        return InputError(f"{what}: cannot write into the folder: {cause}; free some space or give a folder on "
                          "another disk")
    return InputError(f"{what}: cannot write into the folder ({cause})")


def output_folder(path) -> Path:
    """The output folder ``path``, created if needed, after checking that it is a folder and
    writable; InputError (before anything is computed) otherwise."""
    out = Path(path)
    if out.exists() and not out.is_dir():
        raise InputError(f"--out {out}: is a file, not a folder (give a folder; it is created if missing)")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise InputError(f"--out {out}: a part of the path is a file, not a folder") from None
    except NotADirectoryError:
        raise InputError(f"--out {out}: a part of the path is a file, not a folder") from None
    except OSError as exc:     # permission, read-only file system, full disk: named from the error number
        from ..output.io import write_failure

        existing = next((a for a in out.absolute().parents if a.exists()), Path("/"))
        _, cause = write_failure(existing, exc)
        raise InputError(f"--out {out}: cannot create the folder ({cause})") from None
    problem = write_problem(out)
    if problem is not None:
        raise _not_writable(f"--out {out}", out, problem)
    return out


def _image_formats() -> dict:
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.backend_bases import FigureCanvasBase

    return FigureCanvasBase.get_supported_filetypes()


def check_image_path(path) -> Path:
    """A chart file to write: its extension a format matplotlib writes, its folder existing and
    writable, and not a folder itself; InputError otherwise."""
    p = Path(path)
    if p.is_dir():
        raise InputError(f"{p}: is a folder; give an image file name such as {p / 'chart.png'}")
    ext = p.suffix.lower().lstrip(".")
    formats = _image_formats()
    if ext not in formats:
        raise InputError(f"{p}: unknown image extension {('.' + ext) if ext else '(none)'}; use one of "
                         f"{', '.join('.' + f for f in sorted(formats))}")
    folder = p.parent
    if not folder.is_dir():
        raise InputError(f"{p}: the folder {folder} does not exist")
    problem = write_problem(folder)
    if problem is not None:
        raise _not_writable(str(p), folder, problem)
    if p.exists() and not os.access(p, os.W_OK):
        raise InputError(f"{p}: the file is not writable (permission denied); make it writable or give another name")
    return p


@contextmanager
def heartbeat(what: str, *, every: float = 10.0, quiet: float = 1.0):
    """Log "<what> ..." once the block has run ``quiet`` seconds, then "... <what>: N s" every
    ``every`` seconds (a long solve that reports nothing itself still shows it is alive), and
    its duration at the end; a block done within ``quiet`` seconds logs nothing."""
    stop = threading.Event()
    t0 = time.perf_counter()
    started = threading.Event()

    def beat():
        if stop.wait(quiet):
            return
        log.info("  %s ...", what)
        started.set()
        while not stop.wait(every):
            log.info("    ... %s: %.0f s", what, time.perf_counter() - t0)

    th = threading.Thread(target=beat, daemon=True, name="homtex-heartbeat")
    th.start()
    try:
        yield
    finally:
        stop.set()
        th.join()
    if started.is_set():
        log.info("  %s: done in %.1f s", what, time.perf_counter() - t0)
