"""`ProcessExecutor`: trials in local worker processes (`trunkslam reproduce --workers N`).

Workers do not fight over the cores:
- one BLAS/OpenMP thread each: the workers are started ("spawn", a fresh interpreter, not a
  fork of this one) with OMP_NUM_THREADS, OPENBLAS_NUM_THREADS, MKL_NUM_THREADS and
  NUMBA_NUM_THREADS at 1, so their numpy loads its BLAS with one thread;
- numba's on-disk cache (`@njit(cache=True)`): this process compiles (or loads) every kernel
  before the workers start (`warm_kernels`), so the workers load it instead of each compiling
  the same kernels at once, and each worker loads it once, when it starts.

Workers die with their parent: a killed main process (`kill -9`, the OOM killer) leaves no
worker computing for nobody. Each worker asks the kernel for SIGKILL when its parent ends
(Linux `prctl(PR_SET_PDEATHSIG)`), and a watchdog thread in it polls its parent (`os.getppid`
changes when the parent is gone) as the portable fallback. A run that ends by an exception or
an interruption (Ctrl-C, SIGTERM: `experiments.exec.signals`) stops its workers at once
instead of waiting for their trials.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import logging
import os
import signal
import sys
import threading
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from contextlib import contextmanager
from multiprocessing import get_context

from experiments.exec.once import warn_once_per_process
from experiments.exec.trials import Executor, run_chunk

__all__ = ["ONE_THREAD", "ProcessExecutor", "warm_kernels"]

log = logging.getLogger(__name__)

ONE_THREAD = {
    "OMP_NUM_THREADS": "1",
    "OPENBLAS_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
    "NUMEXPR_NUM_THREADS": "1",
    "NUMBA_NUM_THREADS": "1",
}


def warm_kernels() -> None:
    """Compile, or load from numba's cache, every extractor kernel (one small scan through each
    method)."""
    import numpy as np

    from features import METHODS, Scan, extract_features

    angles = np.linspace(-np.pi / 2, np.pi / 2, 181)
    # a wall at 8 m with a trunk of radius 0.3 m at 5 m straight ahead
    ranges = 8.0 / np.maximum(np.cos(angles), 0.2)
    d = 5.0 * np.sin(np.abs(angles))
    on = d < 0.3
    ranges[on] = 5.0 * np.cos(angles[on]) - np.sqrt(0.09 - d[on] ** 2)
    scan = Scan(ranges, angle_min_rad=-np.pi / 2, angle_increment_rad=np.pi / 180)
    for m in METHODS:
        extract_features(scan, m)


_PR_SET_PDEATHSIG = 1  # linux/prctl.h
WATCHDOG_PERIOD_S = 0.5


def die_with_parent(parent_pid: int) -> None:
    """End this process when the process `parent_pid` (its parent) ends: the kernel sends it
    SIGKILL (Linux, `prctl(PR_SET_PDEATHSIG)`), and a daemon thread checks every
    WATCHDOG_PERIOD_S that the parent is still its parent (elsewhere, or should the kernel's
    signal not come). A parent already gone: ends now."""
    if sys.platform.startswith("linux"):
        try:
            libc = ctypes.CDLL(ctypes.util.find_library("c") or None, use_errno=True)
            libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
        except (OSError, AttributeError):
            pass
    if os.getppid() != parent_pid:  # the parent died before the request was made
        os._exit(1)

    def watch() -> None:
        while os.getppid() == parent_pid:
            threading.Event().wait(WATCHDOG_PERIOD_S)
        os._exit(1)

    threading.Thread(target=watch, name="parent-watchdog", daemon=True).start()


def _init_worker(parent_pid: int) -> None:
    die_with_parent(parent_pid)
    os.environ.update(ONE_THREAD)  # for anything the worker starts in turn
    warn_once_per_process()
    warm_kernels()


@contextmanager
def _environ(values: dict):
    old = {k: os.environ.get(k) for k in values}
    os.environ.update(values)
    try:
        yield
    finally:
        for k, v in old.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


class ProcessExecutor(Executor):
    """`workers` local processes, started on first use and kept until `close`."""

    name = "processes"

    def __init__(self, workers: int) -> None:
        self.workers = int(workers)
        self._pool: ProcessPoolExecutor | None = None

    def _start(self) -> ProcessPoolExecutor:
        if self._pool is None:
            warm_kernels()  # the cache the workers load; compiled here once if empty
            with _environ(ONE_THREAD):  # inherited by the workers, started in this block
                self._pool = ProcessPoolExecutor(
                    self.workers,
                    mp_context=get_context("spawn"),
                    initializer=_init_worker,
                    initargs=(os.getpid(),),
                )
                for f in [self._pool.submit(os.getpid) for _ in range(self.workers)]:
                    f.result()
            log.info("%d worker processes started", self.workers)
        return self._pool

    def _submit(self, fn, chunks):
        pool = self._start()
        pending = {pool.submit(run_chunk, fn, c): c for c in chunks}

        def cancel() -> None:
            for f in pending:
                f.cancel()

        return self._finished(pending, cancel), cancel

    @staticmethod
    def _finished(pending: dict, cancel):
        try:
            while pending:
                done, _ = wait(pending, return_when=FIRST_COMPLETED)
                for f in done:
                    chunk = pending.pop(f)
                    try:
                        out = f.result()
                    except Exception as exc:  # a worker died, a record that does not pickle
                        out = [(i, False, (f"{type(exc).__name__}: {exc}", "")) for i, *_ in chunk]
                    yield chunk, out
        finally:
            cancel()

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None

    def stop(self) -> None:
        """Stop the workers now (their running trials are dropped), then close."""
        if self._pool is not None:
            for p in list(getattr(self._pool, "_processes", {}).values()):  # no public handle
                p.terminate()
        self.close()

    def __exit__(self, exc_type, *exc) -> None:
        """An exception or an interruption (Ctrl-C, SIGTERM) stops the workers at once; a run
        that ended waits for them to finish."""
        if exc_type is None:
            self.close()
        else:
            self.stop()
