"""Stop signals as Ctrl-C: SIGTERM (what `timeout`, batch schedulers and `docker stop` send) and
SIGHUP (a closed terminal or SSH session) raise `KeyboardInterrupt` in the main thread, so that a
command stopped by them takes the clean-up path of Ctrl-C: temporary files and folders removed,
the previous outputs left as they were, worker processes stopped. The CLI then ends with
`error: stopped by SIGTERM; ...` and exit code 128 + the signal's number (143, 129), as a shell
reports a command its signal ended (Ctrl-C: 130).
Their default action would end the process at once and leave `.NAME.partial-*` folders behind.

A signal the caller ignores stays ignored (`nohup` ignores SIGHUP; a shell's background job
ignores SIGINT); a handler someone else installed stays too. Only the main thread can install
handlers: elsewhere this does nothing.

A signal that arrives while a numba kernel runs is handled as the kernel returns, and there
Python code that numba's or llvmlite's C code calls back may be running: numba unpickles the
constants of a kernel's results as it boxes them (`_numba_unpickle`), llvmlite notifies its
object cache while it compiles. An exception raised in such a callback becomes a `SystemError`
traceback or is printed and dropped ("Exception ignored ..."): the stop would be a crash, or
lost. So the handler does not raise there: it sends the signal again `RETRY_S` later, by which
time the callback has returned (issue 43).
"""

from __future__ import annotations

import os
import signal
import threading
from collections.abc import Callable

__all__ = ["STOP_SIGNALS", "Stopped", "interrupt_on_stop_signals"]

STOP_SIGNALS = tuple(getattr(signal, n) for n in ("SIGTERM", "SIGHUP") if hasattr(signal, n))


class Stopped(KeyboardInterrupt):
    """A stop signal, raised as Ctrl-C is (KeyboardInterrupt), naming the signal."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


RETRY_S = 0.01  # s: a stop signal that arrived in a numba or llvmlite callback is sent again
_CALLBACK_PACKAGES = ("numba.", "llvmlite.")


def _raise(signum, frame) -> None:
    module = frame.f_globals.get("__name__", "") if frame is not None else ""
    if module.startswith(_CALLBACK_PACKAGES):  # maybe called back from C: raise once out of it
        again = threading.Timer(RETRY_S, os.kill, (os.getpid(), signum))
        again.daemon = True
        again.start()
        return
    raise Stopped(signum)


def interrupt_on_stop_signals() -> Callable[[], None]:
    """Make SIGTERM and SIGHUP raise `Stopped` (a KeyboardInterrupt) in this process, where
    their handler is the default; returns the function that puts the previous handlers back."""
    if threading.current_thread() is not threading.main_thread():
        return lambda: None
    previous = {}
    for sig in STOP_SIGNALS:
        if signal.getsignal(sig) is signal.SIG_DFL:
            previous[sig] = signal.signal(sig, _raise)

    def restore() -> None:
        for sig, handler in previous.items():
            if signal.getsignal(sig) is _raise:
                signal.signal(sig, handler)

    return restore
