"""Progress of long loops on stderr, with `rich.progress` (installed with typer).

On a terminal: one bar per task with done/total, elapsed time and the estimated time left.
Otherwise (a log file, CI): a plain line when a task starts, at most every `every_s` seconds,
and when it ends. With the `trunkslam.progress` logger at INFO (`trunkslam -v`), those lines are
logged instead, on a terminal too (above the bars).
"""

from __future__ import annotations

import logging
import sys
import time

from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)
from rich.progress import Progress as RichProgress

__all__ = ["CONSOLE", "Progress"]

CONSOLE = Console(stderr=True)  # shared with the CLI's log handler, so logs print above bars
log = logging.getLogger("trunkslam.progress")


class Progress:
    """A callable progress(description, done, total) for `RunContext.progress` and the like;
    use it as a context manager (the bars are drawn until it exits)."""

    def __init__(self, every_s: float = 10.0, console: Console | None = None) -> None:
        self.console = console or CONSOLE
        self.tty = self.console.is_terminal
        self.every_s = float(every_s)
        self._bars: RichProgress | None = None
        self._tasks: dict[str, int] = {}
        self._started: dict[str, float] = {}
        self._last_line: dict[str, float] = {}

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        if self._bars is not None:
            self._bars.stop()
            self._bars = None

    def __call__(self, desc: str, done: int, total: int) -> None:
        now = time.perf_counter()
        first = desc not in self._started
        if first:
            self._started[desc] = now
        if self.tty:
            self._bar(desc, done, total)
        if first or done >= total or now - self._last_line.get(desc, now) >= self.every_s:
            self._last_line[desc] = now
            line = self._line(desc, done, total, now - self._started[desc])
            if log.isEnabledFor(logging.INFO):
                log.info("%s", line)
            elif not self.tty:
                sys.stderr.write(line + "\n")
                sys.stderr.flush()

    def _bar(self, desc: str, done: int, total: int) -> None:
        if self._bars is None:
            columns = (  # description, bar, done/total, elapsed and remaining time
                TextColumn("{task.description:<28}"),
                BarColumn(),
                MofNCompleteColumn(),
                TextColumn("elapsed"),
                TimeElapsedColumn(),
                TextColumn("left"),
                TimeRemainingColumn(),
            )
            self._bars = RichProgress(*columns, console=self.console)
            self._bars.start()
        if desc not in self._tasks:
            self._tasks[desc] = self._bars.add_task(desc, total=total)
        self._bars.update(self._tasks[desc], completed=done, total=total)

    @staticmethod
    def _line(desc: str, done: int, total: int, elapsed_s: float) -> str:
        frac = done / total if total else 1.0
        eta = f", about {elapsed_s * (1 - frac) / frac:.0f} s left" if 0 < frac < 1 else ""
        return f"{desc}: {done}/{total} ({100 * frac:.0f}%), {elapsed_s:.1f} s{eta}"
