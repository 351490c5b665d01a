"""`make_executor`: the executor a command's `--workers` / `--dask` ask for. Apart from
`trials` (the interface), which the executors import, so no module imports its importers."""

from __future__ import annotations

import os

from experiments.errors import ConfigError
from experiments.exec.local import ProcessExecutor
from experiments.exec.trials import Executor, SerialExecutor

__all__ = ["make_executor"]


def make_executor(workers: int | None = None, dask: str | None = None) -> Executor:
    """The executor `--workers N` / `--dask ADDRESS` ask for: a Dask scheduler when an address
    is given, else N local processes (None: every core this process may use), else (N = 1) this
    process. The caller closes it."""
    if dask:
        from experiments.exec.cluster import DaskExecutor  # dask loads only when asked for

        return DaskExecutor(dask)
    if workers is None:
        workers = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None
        workers = workers or os.cpu_count() or 1
    if workers < 1:
        raise ConfigError(f"--workers must be at least 1, got {workers}")
    if workers == 1:
        return SerialExecutor()
    return ProcessExecutor(workers)
