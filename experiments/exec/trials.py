"""Trials, their seeds, the executor interface and the in-process executor.

`Executor.map(fn, configs, seeds)` runs trial i as `fn(configs[i], seeds[i])`, in chunks of
trials sent to wherever the executor runs them; it returns the records in trial order once all
have finished, reporting progress as chunks finish. A trial that raises does not stop the
others: `TrialsFailed` is raised after all of them, naming each failed trial with its index,
its seed and its error, and carries the records of the others.
"""

from __future__ import annotations

import copy
import logging
import math
import os
import traceback
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any

from experiments.errors import ConfigError, TrunkslamError

__all__ = [
    "Executor",
    "SerialExecutor",
    "TrialFailure",
    "TrialsFailed",
    "describe_seed",
    "make_executor",
    "run_chunk",
    "spawn_seeds",
]

log = logging.getLogger(__name__)

Progress = Callable[[str, int, int], None]
# one task of a chunk: (trial index, configuration, seed)
Task = tuple[int, Any, Any]


def spawn_seeds(seed, n: int) -> list:
    """n independent trial seeds: `SeedSequence.spawn(n)` of `seed`.

    seed: a `numpy.random.SeedSequence`, an int (the root of a new one), or a
    `numpy.random.Generator`, whose bit generator's seed sequence is spawned: the i-th seed
    then gives exactly the generator `rng.spawn(n)[i]` would (`default_rng(seeds[i])`), so a
    study that drew its runs that way keeps its numbers. Like `spawn`, each call hands out the
    next children: call it once per study."""
    import numpy as np

    if isinstance(seed, np.random.Generator):
        seed = seed.bit_generator.seed_seq
    elif not isinstance(seed, np.random.SeedSequence):
        seed = np.random.SeedSequence(seed)
    return seed.spawn(n)


def describe_seed(seed) -> str:
    """A seed as the text that rebuilds it (`numpy.random.SeedSequence(...)`), or 'none'."""
    if seed is None:
        return "none"
    entropy = getattr(seed, "entropy", seed)
    key = tuple(getattr(seed, "spawn_key", ()))
    return f"SeedSequence(entropy={entropy}, spawn_key={key})"


@dataclass(frozen=True)
class TrialFailure:
    """One trial that raised: its index in the study, its seed (`describe_seed`), the error
    (`Type: message`) and the traceback from where it ran."""

    index: int
    seed: str
    error: str
    traceback: str = ""

    def __str__(self) -> str:
        return f"trial {self.index} (seed {self.seed}): {self.error}"


class TrialsFailed(TrunkslamError):
    """Trials of a study raised. `failures` names each (index, seed, error); `records` holds
    the records of all trials in order, None where a trial failed: the others are not lost."""

    def __init__(self, desc: str, failures: list[TrialFailure], records: list) -> None:
        self.desc = desc
        self.failures = failures
        self.records = records
        shown = "; ".join(str(f) for f in failures[:5])
        more = f"; and {len(failures) - 5} more" if len(failures) > 5 else ""
        super().__init__(
            f"{len(failures)} of {len(records)} trials of {desc!r} failed: {shown}{more}"
        )


def run_chunk(fn: Callable, tasks: Sequence[Task]) -> list[tuple[int, bool, Any]]:
    """Run the trials of one chunk where the executor put it: (index, ok, record) per trial,
    with (error, traceback) as the record of a trial that raised (exceptions need not pickle).
    Each trial gets its own copy of its seed: a trial that spawns from it (`Generator.spawn`)
    counts its children from zero, whether or not the seed object is shared (in this process,
    or within a pickled chunk)."""
    out = []
    for i, config, seed in tasks:
        try:
            out.append((i, True, fn(config, copy.deepcopy(seed))))
        except Exception as exc:  # a failed trial is reported, the chunk goes on
            out.append((i, False, (f"{type(exc).__name__}: {exc}", traceback.format_exc())))
    return out


class Executor:
    """Runs trials somewhere. Subclasses say where (`_run`); `map` is the same for all.

    workers: how many trials run at once (the chunk size is chosen from it).
    """

    name = "executor"
    workers = 1

    def map(
        self,
        fn: Callable[[Any, Any], Any],
        configs: Sequence,
        seeds: Sequence | None = None,
        *,
        desc: str = "trials",
        progress: Progress | None = None,
        chunksize: int | None = None,
    ) -> list:
        """Records of `fn(configs[i], seeds[i])` for every i, in trial order.

        fn must be a module-level function (it is sent to the workers by reference). seeds:
        one per trial (None: every trial gets None). chunksize: trials sent together (default:
        about four chunks per worker; one trial at a time in this process). Raises
        `TrialsFailed` after all trials when any raised."""
        configs = list(configs)
        n = len(configs)
        seeds = [None] * n if seeds is None else list(seeds)
        if len(seeds) != n:
            raise ConfigError(f"{desc}: {n} trial configurations but {len(seeds)} seeds")
        tasks = [(i, configs[i], seeds[i]) for i in range(n)]
        size = chunksize or (1 if self.workers == 1 else math.ceil(n / (4 * self.workers)))
        size = max(size, 1)
        chunks = [tasks[a : a + size] for a in range(0, n, size)]
        records: list = [None] * n
        failures: list[TrialFailure] = []
        done = 0
        if progress is not None:
            progress(desc, 0, n)
        for chunk, out in self._run(fn, chunks):
            for i, ok, value in out:
                if ok:
                    records[i] = value
                else:
                    failures.append(TrialFailure(i, describe_seed(seeds[i]), *value))
                    log.error(
                        "%s: trial %d (seed %s) failed:\n%s", desc, i, failures[-1].seed, value[1]
                    )
            done += len(chunk)
            if progress is not None:
                progress(desc, done, n)
        if failures:
            raise TrialsFailed(desc, sorted(failures, key=lambda f: f.index), records)
        return records

    def _run(
        self, fn: Callable, chunks: list[list[Task]]
    ) -> Iterator[tuple[list[Task], list[tuple[int, bool, Any]]]]:
        """Yield (chunk, run_chunk's output) as chunks finish, in any order."""
        raise NotImplementedError

    def describe(self) -> dict:
        """What ran the trials, for the manifest."""
        return {"executor": self.name, "workers": self.workers}

    def close(self) -> None:
        """Release the workers (the executor cannot be used afterwards)."""

    def __enter__(self) -> Executor:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class SerialExecutor(Executor):
    """Every trial in this process, one after the other (`--workers 1`)."""

    name = "serial"

    def _run(self, fn, chunks):
        for chunk in chunks:
            yield chunk, run_chunk(fn, chunk)


def make_executor(workers: int | None = None, dask: str | None = None) -> Executor:
    """The executor `--workers N` / `--dask ADDRESS` ask for: a Dask scheduler when an address
    is given, else N local processes (None: every core this process may use), else (N = 1) this
    process. The caller closes it."""
    if dask:
        from experiments.exec.cluster import DaskExecutor

        return DaskExecutor(dask)
    if workers is None:
        workers = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None
        workers = workers or os.cpu_count() or 1
    if workers < 1:
        raise ConfigError(f"--workers must be at least 1, got {workers}")
    if workers == 1:
        return SerialExecutor()
    from experiments.exec.local import ProcessExecutor

    return ProcessExecutor(workers)
