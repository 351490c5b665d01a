"""Progress of long loops on stderr, with `rich.progress` (installed with typer).

On a terminal: one bar per task with done/total, elapsed time and the estimated time left.
Otherwise (a log file, CI): a plain line when a task starts, at most every `every_s` seconds,
and when it ends. With the `trunkslam.progress` logger at INFO (`trunkslam -v`), those lines are
logged instead, on a terminal too (above the bars).

Never silent for longer than `every_s` (10 s): while no count comes (a long trial, a compile)
a heartbeat line says what is still running and for how long (in a log file; on a terminal the
bars keep their clocks running). Before numba's first compile in the process a one-time line
says so (`experiments.render.compiling`). The time left is estimated from the rate since the
task's first count, once `ETA_AFTER` counts have come since then: the time before the first
count (start-up, compiling) does not enter the rate, and a first line never says "about 0 s
left".
"""

from __future__ import annotations

import logging
import sys
import threading
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

from experiments.render.compiling import (
    compile_seconds,
    compiling_now,
    take_early_notice,
    watch_compiles,
)

__all__ = ["CONSOLE", "ETA_AFTER", "Progress"]

ETA_AFTER = 3  # counts since a task's first one before its time left is estimated

CONSOLE = Console(stderr=True)  # shared with the CLI's log handler, so logs print above bars
log = logging.getLogger("trunkslam.progress")


class Progress:
    """A callable progress(description, done, total) for `RunContext.progress` and the like;
    use it as a context manager (the bars are drawn until it exits)."""

    def __init__(
        self,
        every_s: float = 10.0,
        console: Console | None = None,
        heartbeat_s: float | None = None,
    ) -> None:
        """every_s: a task's lines at most this often (0: every count); heartbeat_s: a line
        after this long without one [default: every_s, or 10 s when every_s is 0]."""
        self.console = console or CONSOLE
        self.tty = self.console.is_terminal
        self.every_s = float(every_s)
        self.heartbeat_s = float(heartbeat_s or every_s or 10.0)
        self._bars: RichProgress | None = None
        self._tasks: dict[str, int] = {}
        self._started: dict[str, float] = {}
        self._first: dict[str, tuple[float, int]] = {}  # (time, count) of a task's first count
        self._compiled: dict[str, float] = {}  # compile_seconds() when each task started
        self._counts: dict[str, tuple[int, int]] = {}  # the last (done, total) of each task
        self._last_line: dict[str, float] = {}
        early = take_early_notice()  # a notice said before the imports: silent since then
        self._last_said = self._last_event = time.perf_counter() if early is None else early
        self._compiled_at_event = compile_seconds()  # as of _last_event
        self._lock = threading.RLock()
        self._stop = threading.Event()
        self._beat: threading.Thread | None = None

    def __enter__(self) -> Progress:
        watch_compiles(self.say)
        self._beat = threading.Thread(target=self._heartbeat, name="progress", daemon=True)
        self._beat.start()
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        self._stop.set()
        if self._beat is not None and self._beat is not threading.current_thread():
            self._beat.join()
        self._beat = None
        if self._bars is not None:
            self._bars.stop()
            self._bars = None

    def __call__(self, desc: str, done: int, total: int) -> None:
        with self._lock:
            now = time.perf_counter()
            first = desc not in self._started
            if first:  # a first count of 0 starts now; a later one, at the last event
                self._started[desc] = now if done == 0 else self._last_event
                self._compiled[desc] = compile_seconds() if done == 0 else self._compiled_at_event
            if desc not in self._first and done > 0:
                self._first[desc] = (now, done)
            self._counts[desc] = (done, total)
            self._last_event, self._compiled_at_event = now, compile_seconds()
            if self.tty:
                self._bar(desc, done, total)
            if first or done >= total or now - self._last_line.get(desc, now) >= self.every_s:
                self._last_line[desc] = now
                self.say(self._line(desc, done, total, *self._clock(desc, now)))

    def say(self, line: str) -> None:
        """Write one line as the progress lines are written (a log record with -v; stderr off a
        terminal; above the bars on one)."""
        with self._lock:
            self._last_said = time.perf_counter()
            if log.isEnabledFor(logging.INFO):
                log.info("%s", line)
            elif not self.tty:
                sys.stderr.write(line + "\n")
                sys.stderr.flush()
            else:
                self.console.print(line, highlight=False, markup=False)

    def _clock(self, desc: str, now: float) -> tuple[float, float, float | None]:
        """(seconds the task has run, compiling left out; seconds of it spent compiling;
        seconds left or None)."""
        compiled = compile_seconds() - self._compiled[desc]
        return now - self._started[desc] - compiled, compiled, self._eta(desc)

    def _eta(self, desc: str) -> float | None:
        """Seconds left at the rate since the task's first count; None until ETA_AFTER counts
        have come since then, or once done."""
        if desc not in self._first:
            return None
        (t1, n1), (done, total) = self._first[desc], self._counts[desc]
        if done - n1 < ETA_AFTER or done >= total:
            return None
        return (total - done) * (time.perf_counter() - t1) / (done - n1)

    def _heartbeat(self) -> None:
        """After `heartbeat_s` without a line: say what is still running (off a terminal, or on
        one before any bar is drawn; the bars show their own clocks)."""
        while not self._stop.wait(min(self.heartbeat_s, 1.0) / 4):
            with self._lock:
                now = time.perf_counter()
                recent = now - self._last_said < self.heartbeat_s
                if recent or (self.tty and self._bars is not None):
                    continue
                self.say(self._still(now))

    def _still(self, now: float) -> str:
        """The heartbeat's line: the unfinished task counted last, with its count, else that
        something is running."""
        doing = "compiling kernels" if compiling_now() else "working"
        running = [d for d, (n, t) in self._counts.items() if n < t]
        if not running:
            since = "the last count" if self._counts else "the start"
            return f"still {doing} ({now - self._last_event:.0f} s since {since})"
        desc = max(running, key=lambda d: self._last_line.get(d, 0.0))
        done, total = self._counts[desc]
        return f"{self._line(desc, done, total, *self._clock(desc, now))} (still {doing})"

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
    def _line(
        desc: str, done: int, total: int, elapsed_s: float, compiled_s: float, eta_s: float | None
    ) -> str:
        frac = done / total if total else 1.0
        compiled = f" (+ {compiled_s:.0f} s compiling)" if compiled_s >= 0.5 else ""
        eta = "" if eta_s is None else f", about {eta_s:.0f} s left"
        return f"{desc}: {done}/{total} ({100 * frac:.0f}%), {elapsed_s:.1f} s{compiled}{eta}"
