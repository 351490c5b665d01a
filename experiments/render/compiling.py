"""numba's compilations in this process: said once before the first, and timed apart.

The kernels are compiled on their first call after an install (`@njit(cache=True)`), then
loaded from numba's cache. The first compile of a process takes a minute or more and reports
no count, so `watch_compiles` has a one-time line said before it ("compiling kernels ...")
and `compile_seconds` gives the seconds spent compiling so far, which a run's reported time
leaves out (and reports apart). A kernel loaded from the cache is no compile: numba's
"numba:compile" event (`numba.core.event`) comes only on a cache miss.

numba is not imported here: `watch_compiles` registers the listener only once numba is loaded
(the command's own imports load it), so a command that never compiles pays nothing.
"""

from __future__ import annotations

import sys
import threading
import time
from collections.abc import Callable

__all__ = [
    "COMPILING_NOTICE",
    "claim_notice",
    "compile_seconds",
    "compiling_now",
    "take_early_notice",
    "watch_compiles",
]

COMPILING_NOTICE = (
    "compiling kernels (first run after an install only, then cached; a minute or two, with "
    "no count meanwhile)"
)


class _Clock:
    """Seconds spent in top-level compilations (a kernel's callees compile inside its own)."""

    def __init__(self) -> None:
        self.total_s = 0.0
        self.depth = 0
        self.started = 0.0
        self.said = False
        self.said_early_at: float | None = None  # when `claim_notice` took the notice
        self.say: Callable[[str], None] | None = None
        self.registered = False
        self.lock = threading.Lock()

    def on_start(self) -> None:
        say = None
        with self.lock:
            if self.depth == 0:
                self.started = time.perf_counter()
                if not self.said and self.say is not None:
                    self.said, say = True, self.say
            self.depth += 1
        if say is not None:  # outside the lock: `say` takes the progress display's lock, whose
            say(COMPILING_NOTICE)  # heartbeat thread may be waiting here for `seconds`

    def on_end(self) -> None:
        with self.lock:
            self.depth -= 1
            if self.depth == 0:
                self.total_s += time.perf_counter() - self.started

    def seconds(self) -> float:
        with self.lock:
            running = time.perf_counter() - self.started if self.depth else 0.0
            return self.total_s + running


_CLOCK = _Clock()


def watch_compiles(say: Callable[[str], None] | None = None) -> bool:
    """Time numba's compilations from now on, and call `say(COMPILING_NOTICE)` before the first
    of this process (once per process). Does nothing until numba is imported; returns whether
    the watch is on."""
    if say is not None:
        _CLOCK.say = say
    if "numba" not in sys.modules:
        return False
    if not _CLOCK.registered:
        from numba.core import event

        class _Listener(event.Listener):
            def on_start(self, ev) -> None:  # noqa: ARG002 (numba's signature)
                _CLOCK.on_start()

            def on_end(self, ev) -> None:  # noqa: ARG002
                _CLOCK.on_end()

        event.register("numba:compile", _Listener())
        _CLOCK.registered = True
    return True


def claim_notice() -> bool:
    """Take the one-time notice to say it now, before any compile (`experiments.render.
    cold_start`): whether it was still unsaid; the first compile then says nothing."""
    with _CLOCK.lock:
        unsaid, _CLOCK.said = not _CLOCK.said, True
        if unsaid:
            _CLOCK.said_early_at = time.perf_counter()
    return unsaid


def take_early_notice() -> float | None:
    """The `time.perf_counter()` of a notice said by `claim_notice` that no progress display
    has counted its silence from yet (then no longer), else None."""
    with _CLOCK.lock:
        at, _CLOCK.said_early_at = _CLOCK.said_early_at, None
    return at


def compile_seconds() -> float:
    """Seconds this process has spent compiling numba kernels since `watch_compiles` (0.0 when
    not watched)."""
    return _CLOCK.seconds()


def compiling_now() -> bool:
    """Whether numba is compiling in this process at this moment (as watched)."""
    return _CLOCK.depth > 0
