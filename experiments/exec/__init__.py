"""Where the trials of a study run: one executor abstraction for every experiment's trial loop.

A trial is a pure function `fn(config, seed)` of its configuration and its own seed (a
`numpy.random.SeedSequence` from `SeedSequence.spawn`, or None for a deterministic trial) that
returns a small, picklable record. An executor runs a list of them and returns the records in
trial order, whatever finished first, so a study reduces its records in the same order and gets
the same numbers, bit for bit, on one core, on all local cores or on a Dask cluster.

- `trials`: `Executor` (the interface, and the in-process `SerialExecutor`), `Batch` (trials
  handed over by `Executor.submit`, running while this process goes on), `spawn_seeds`,
  `TrialsFailed` (trials that raised, each with its seed; the others' records kept)
- `local`: `ProcessExecutor`, local worker processes with one BLAS thread each
- `cluster`: `DaskExecutor`, a `dask.distributed` scheduler (the only module importing dask)
- `make_executor(workers, dask)`: what `--workers` / `--dask` ask for

Nothing here imports numpy at module level: a worker process sets its thread limits before
numpy loads. The names above load on first use (`__getattr__`), so importing one small module of
the package (`once`, `threads`, `signals`) loads no executor.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from experiments.exec.choose import make_executor
    from experiments.exec.trials import (
        Batch,
        Executor,
        SerialExecutor,
        TrialFailure,
        TrialsFailed,
        describe_seed,
        spawn_seeds,
    )

__all__ = [
    "Batch",
    "Executor",
    "SerialExecutor",
    "TrialFailure",
    "TrialsFailed",
    "describe_seed",
    "make_executor",
    "spawn_seeds",
]


def __getattr__(name: str):
    """The package's names, loaded when first asked for: the command line imports
    `experiments.exec.once`, `threads` and `signals` on every command, and would otherwise pay
    for the executors (multiprocessing, concurrent.futures) it mostly does not use."""
    if name not in __all__:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    module = "choose" if name == "make_executor" else "trials"
    return getattr(importlib.import_module(f"experiments.exec.{module}"), name)
