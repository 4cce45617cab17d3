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

__all__ = ["check_image_path", "heartbeat", "output_folder", "safe_stem", "stem_of", "writable"]

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


def writable(folder) -> bool:
    """Can this process create a file in ``folder``? (tried: os.access says yes to root everywhere)"""
    try:
        fd, probe = tempfile.mkstemp(prefix=".homtex-write-test.", dir=folder)
    except OSError:
        return False
    os.close(fd)
    os.unlink(probe)
    return True


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
    except PermissionError:
        raise InputError(f"--out {out}: cannot create the folder (permission denied)") from None
    except OSError as exc:
        raise InputError(f"--out {out}: cannot create the folder ({exc.strerror or exc})") from None
    if not writable(out):
        raise InputError(f"--out {out}: the folder is not writable (permission denied or a read-only file system)")
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
    if not writable(folder) or (p.exists() and not os.access(p, os.W_OK)):
        raise InputError(f"{p}: not writable (permission denied or a read-only file system)")
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
