"""Never silent for long (issue 44): a heartbeat while no count comes, a one-time line before
numba's first compile, no time left until it can be estimated, compiling reported apart.

The heartbeat's interval is injected (`Progress(heartbeat_s=...)`): the slow fake trial is a
fraction of a second of silence, not ten seconds."""

from __future__ import annotations

import io
import logging
import sys
import threading
import time

import pytest
from rich.console import Console

import experiments.render.compiling as compiling
import experiments.render.progress as progress_module
from experiments.render.progress import ETA_AFTER, Progress


@pytest.fixture(autouse=True)
def _plain_lines(caplog):
    """Progress writes plain lines (not log records), whatever `-v` an earlier test set."""
    with caplog.at_level(logging.WARNING, logger="trunkslam.progress"):
        yield


class _Stamped(io.StringIO):
    """stderr that remembers when each line was written."""

    def __init__(self) -> None:
        super().__init__()
        self.stamps: list[tuple[float, str]] = []

    def write(self, text: str) -> int:
        if text.strip():
            self.stamps.append((time.perf_counter(), text.strip()))
        return super().write(text)


def _off_terminal() -> Console:
    return Console(file=io.StringIO(), force_terminal=False)


def test_a_slow_trial_gets_heartbeats_off_a_terminal(monkeypatch):
    """One trial of three runs 1 s without a count (the fake trial sleeps); with a heartbeat of
    0.1 s the log gets a line at least every few tenths, saying which task is still running."""
    err = _Stamped()
    monkeypatch.setattr(sys, "stderr", err)
    start = time.perf_counter()
    with Progress(every_s=10.0, console=_off_terminal(), heartbeat_s=0.1) as progress:
        progress("trials", 0, 3)
        time.sleep(1.0)  # the slow fake trial: no count meanwhile
        progress("trials", 1, 3)
        progress("trials", 3, 3)
    beats = [t for t, line in err.stamps if line.endswith("(still working)")]
    assert len(beats) >= 3, err.getvalue()  # about 9 expected; 3 allows a loaded machine
    assert all("trials: 0/3 (0%)" in line for _, line in err.stamps if "still" in line)
    assert err.stamps[-1][1].startswith("trials: 3/3 (100%)")
    times = [start] + [t for t, _ in err.stamps]
    assert max(b - a for a, b in zip(times, times[1:])) < 0.6  # a heartbeat is 0.1 s; slack


def test_a_heartbeat_before_any_count_says_so(monkeypatch):
    err = _Stamped()
    monkeypatch.setattr(sys, "stderr", err)
    with Progress(console=_off_terminal(), heartbeat_s=0.05):
        time.sleep(0.3)  # imports, a compile: no task has counted yet
    assert err.stamps and all(
        "still working" in ln and "since the start" in ln for _, ln in err.stamps
    )


def test_no_heartbeat_while_lines_come():
    err = _Stamped()
    old, sys.stderr = sys.stderr, err
    try:
        with Progress(every_s=0.0, console=_off_terminal(), heartbeat_s=5.0) as progress:
            for k in range(1, 21):
                progress("slam", k, 20)
    finally:
        sys.stderr = old
    assert len(err.stamps) == 20 and not any("still" in line for _, line in err.stamps)


def _fake_clock(monkeypatch) -> list[float]:
    """progress' time.perf_counter, set by hand: [now]."""
    now = [0.0]
    monkeypatch.setattr(progress_module.time, "perf_counter", lambda: now[0])
    return now


def test_no_time_left_until_enough_counts_since_the_first(monkeypatch, capsys):
    """The first count (after start-up or a compile) gives no rate; the time left appears once
    ETA_AFTER more counts have come, from their rate alone."""
    now = _fake_clock(monkeypatch)
    with Progress(every_s=0.0, console=_off_terminal(), heartbeat_s=1e9) as progress:
        for k in range(1, 11):
            now[0] = 100.0 + (k - 1)  # the first count after 100 s, then one a second
            progress("trials", k, 10)
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 10
    assert not any("left" in ln for ln in lines[:ETA_AFTER]), lines
    assert "about 6 s left" in lines[ETA_AFTER]  # 3 counts in 3 s since the first: 1 s each
    assert "left" not in lines[-1]  # done


def test_compiling_is_said_once_and_left_out_of_the_task_time(monkeypatch, capsys):
    """The notice comes before the first compile of the process only (a kernel's callees
    compile inside it), and a task's time leaves the compiling out and says it apart."""
    clock = compiling._Clock()
    clock.registered = True  # the listener: driven by hand below
    monkeypatch.setattr(compiling, "_CLOCK", clock)
    now = _fake_clock(monkeypatch)
    monkeypatch.setattr(progress_module, "compile_seconds", lambda: 40.0 if now[0] else 0.0)
    with Progress(every_s=0.0, console=_off_terminal(), heartbeat_s=1e9) as progress:
        for _ in range(2):
            clock.on_start()
            clock.on_start()  # a callee compiled inside the kernel's compile
            clock.on_end()
            clock.on_end()
        now[0] = 50.0  # 40 s of it compiling
        progress("slam", 20, 20)
    err = capsys.readouterr().err.splitlines()
    assert err == [compiling.COMPILING_NOTICE, "slam: 20/20 (100%), 10.0 s (+ 40 s compiling)"]


def test_a_real_numba_compile_is_seen_and_timed(monkeypatch):
    numba = pytest.importorskip("numba")
    clock = compiling._Clock()
    monkeypatch.setattr(compiling, "_CLOCK", clock)
    said = []
    assert compiling.watch_compiles(said.append)

    @numba.njit(cache=False)
    def fresh(x):  # never in numba's cache: a compile on its first call
        return x * 2.0 + 1.0

    before = compiling.compile_seconds()
    assert fresh(1.0) == 3.0
    assert said == [compiling.COMPILING_NOTICE] and compiling.compile_seconds() > before
    assert fresh(2.0) == 5.0 and len(said) == 1  # compiled: no second notice


def test_the_heartbeat_thread_ends_with_the_progress():
    with Progress(console=_off_terminal(), heartbeat_s=0.05) as progress:
        beat = progress._beat
        assert beat is not None and beat.is_alive()
    assert not beat.is_alive() and beat not in threading.enumerate()
