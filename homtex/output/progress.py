"""Progress display for long work: a rich progress bar when rich is installed, else a line on
stderr every tenth of the work. One class for studies, compression curves and seam solves."""

from __future__ import annotations

import sys
import time


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
            from rich.progress import BarColumn, MofNCompleteColumn, Progress as _Rich, TimeRemainingColumn

            self.bar = _Rich("[progress.description]{task.description}", BarColumn(), MofNCompleteColumn(),
                             TimeRemainingColumn(), transient=False)
            self.bar.start()
            self.task = self.bar.add_task(description, total=self.total, completed=self.done)
        except ImportError:
            self.bar = None
            print(f"{description}: {self.done}/{self.total} {unit} done", file=sys.stderr)

    def step(self, note: str = "") -> None:
        self.done += 1
        if not self.enabled:
            return
        if self.bar is not None:
            self.bar.update(self.task, advance=1)
            return
        frac = self.done / max(self.total, 1)
        if frac >= self.next_line or self.done == self.total:
            print(f"  {self.done}/{self.total} {self.unit} ({time.perf_counter() - self.t0:.1f} s)"
                  + (f" - {note}" if note else ""), file=sys.stderr)
            self.next_line = frac + 0.1

    def close(self) -> None:
        if self.bar is not None:
            self.bar.stop()
