"""Progress of long work: a rich progress bar when rich is installed, else a log line (INFO on
the ``homtex.progress`` logger) every tenth of the work. One class for studies, compression
curves and seam solves; the command line shows the log lines."""

from __future__ import annotations

import logging
import time

__all__ = ["Progress"]

log = logging.getLogger(__name__)


class Progress:
    """``Progress(total, "study x", unit="points")``; ``step(note="")`` after each item;
    ``close()`` at the end. ``enabled=False`` shows nothing."""

    def __init__(self, total: int, description: str, *, done: int = 0, unit: str = "steps",
                 enabled: bool = True):
        self.total, self.done, self.enabled, self.unit = int(total), int(done), enabled, unit
        self.description = description
        self.bar = None
        self.t0 = time.perf_counter()
        self.next_line = 0.0
        if not enabled:
            return
        try:
            from rich.progress import BarColumn, MofNCompleteColumn, TimeRemainingColumn
            from rich.progress import Progress as _Rich

            self.bar = _Rich("[progress.description]{task.description}", BarColumn(), MofNCompleteColumn(),
                             TimeRemainingColumn(), transient=False)
            self.bar.start()
            self.task = self.bar.add_task(description, total=self.total, completed=self.done)
        except ImportError:  # rich is an optional extra
            self.bar = None
            log.info("%s: %d/%d %s done", description, self.done, self.total, unit)

    def step(self, note: str = "") -> None:
        self.done += 1
        if not self.enabled:
            return
        if self.bar is not None:
            self.bar.update(self.task, advance=1)
            return
        frac = self.done / max(self.total, 1)
        if frac >= self.next_line or self.done == self.total:
            log.info("  %s: %d/%d %s (%.1f s)%s", self.description, self.done, self.total, self.unit,
                     time.perf_counter() - self.t0, f" - {note}" if note else "")
            self.next_line = frac + 0.1

    def close(self) -> None:
        if self.bar is not None:
            self.bar.stop()
