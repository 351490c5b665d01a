"""A stop signal that arrives in a numba or llvmlite callback (issue 43): numba boxes a kernel's
results by calling Python code back (`_numba_unpickle`), llvmlite notifies its object cache while
compiling; an exception raised there became a SystemError traceback or was dropped. The handler
sends the signal again instead, and the stop happens just after, in ordinary code."""

from __future__ import annotations

import signal
import sys
import time

import pytest

from experiments.exec import signals
from experiments.exec.signals import Stopped, interrupt_on_stop_signals


def _frame_of(module: str):
    """A frame whose code belongs to `module` (as the handler sees a callback's frame)."""
    code = compile("_getframe()", f"<{module}>", "eval")
    return eval(code, {"__name__": module, "_getframe": sys._getframe})  # noqa: S307


@pytest.mark.parametrize("module", ["numba.core.serialize", "llvmlite.binding.executionengine"])
def test_a_stop_in_a_callback_is_sent_again_and_stops_after_it(module):
    if signal.getsignal(signal.SIGTERM) is not signal.SIG_DFL:
        pytest.skip("SIGTERM has a handler in this process")
    restore = interrupt_on_stop_signals()
    try:
        assert signals._raise(signal.SIGTERM, _frame_of(module)) is None  # no raise in there
        t0 = time.monotonic()
        with pytest.raises(Stopped) as stop:
            while time.monotonic() - t0 < 5.0:  # the signal comes back RETRY_S later
                time.sleep(0.001)
        assert stop.value.signum == signal.SIGTERM
        assert time.monotonic() - t0 < 1.0
    finally:
        restore()


def test_a_stop_in_ordinary_code_raises_at_once():
    with pytest.raises(Stopped):
        signals._raise(signal.SIGTERM, _frame_of("experiments.pipeline.slam"))
    with pytest.raises(Stopped):
        signals._raise(signal.SIGTERM, None)
