"""Trials, their seeds, the executor interface and the in-process executor.

`Executor.map(fn, configs, seeds)` runs trial i as `fn(configs[i], seeds[i])`, in chunks of
trials sent to wherever the executor runs them; it returns the records in trial order once all
have finished, reporting progress as chunks finish. A trial that raises does not stop the
others: `TrialsFailed` is raised after all of them, naming each failed trial with its index,
its seed and its error, and carries the records of the others. `Executor.submit` is `map`
without the wait: it hands the trials over and returns their `Batch` at once, so this process
can work (render, write) while the workers run them; `Batch.result()` is what `map` returns.
"""

from __future__ import annotations

import copy
import logging
import math
import traceback
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any

from experiments.errors import ConfigError, TrunkslamError

__all__ = [
    "Batch",
    "Executor",
    "SerialExecutor",
    "TrialFailure",
    "TrialsFailed",
    "describe_seed",
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


class Batch:
    """Trials handed to an executor by `Executor.submit`: queued or running where the executor
    runs them while this process goes on. `result()` waits for them and returns their records in
    trial order (reporting progress as chunks finish, raising `TrialsFailed` after all of them
    when any raised), as `map` does; asked again, it gives the same answer. `cancel()` drops the
    chunks not yet started (a batch whose result is no longer wanted)."""

    def __init__(self, desc: str, seeds: list, finished: Iterator, cancel: Callable[[], None]):
        self.desc = desc
        self._seeds = seeds
        self._finished = finished
        self._cancel = cancel
        self._records: list | None = None
        self._failed: TrialsFailed | None = None
        self._cancelled = False

    def result(self, progress: Progress | None = None) -> list:
        """The records, in trial order, once every trial has finished."""
        if self._cancelled:
            raise RuntimeError(f"{self.desc}: the batch was cancelled; it has no result")
        if self._records is None and self._failed is None:
            self._gather(progress)
        if self._failed is not None:
            raise self._failed
        return self._records

    def _gather(self, progress: Progress | None) -> None:
        n = len(self._seeds)
        records: list = [None] * n
        failures: list[TrialFailure] = []
        done = 0
        if progress is not None:
            progress(self.desc, 0, n)
        try:
            for chunk, out in self._finished:
                for i, ok, value in out:
                    if ok:
                        records[i] = value
                    else:
                        failures.append(TrialFailure(i, describe_seed(self._seeds[i]), *value))
                        log.error(
                            "%s: trial %d (seed %s) failed:\n%s",
                            self.desc,
                            i,
                            failures[-1].seed,
                            value[1],
                        )
                done += len(chunk)
                if progress is not None:
                    progress(self.desc, done, n)
        except BaseException:  # interrupted: the rest is not wanted
            self._cancel()
            raise
        if failures:
            failures.sort(key=lambda f: f.index)
            self._failed = TrialsFailed(self.desc, failures, records)
        else:
            self._records = records

    def cancel(self) -> None:
        """Drop the chunks not started yet; the batch has no result afterwards."""
        self._cancel()
        self._cancelled = True


class Executor:
    """Runs trials somewhere. Subclasses say where (`_submit`); `submit` and `map` are the same
    for all.

    workers: how many trials run at once (the chunk size is chosen from it).
    """

    name = "executor"
    workers = 1

    def submit(
        self,
        fn: Callable[[Any, Any], Any],
        configs: Sequence,
        seeds: Sequence | None = None,
        *,
        desc: str = "trials",
        chunksize: int | None = None,
    ) -> Batch:
        """Hand the trials `fn(configs[i], seeds[i])` to the executor and return at once: their
        `Batch`, whose `result()` waits for them. Worker processes and a Dask cluster start them
        now, in submission order after what is already queued; this process
        (`SerialExecutor`) runs them when the result is asked for. Arguments as `map`."""
        configs = list(configs)
        n = len(configs)
        seeds = [None] * n if seeds is None else list(seeds)
        if len(seeds) != n:
            raise ConfigError(f"{desc}: {n} trial configurations but {len(seeds)} seeds")
        tasks = [(i, configs[i], seeds[i]) for i in range(n)]
        size = chunksize or (1 if self.workers == 1 else math.ceil(n / (4 * self.workers)))
        size = max(size, 1)
        chunks = [tasks[a : a + size] for a in range(0, n, size)]
        finished, cancel = self._submit(fn, chunks)
        return Batch(desc, seeds, finished, cancel)

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
        batch = self.submit(fn, configs, seeds, desc=desc, chunksize=chunksize)
        return batch.result(progress)

    def _submit(
        self, fn: Callable, chunks: list[list[Task]]
    ) -> tuple[Iterator[tuple[list[Task], list[tuple[int, bool, Any]]]], Callable[[], None]]:
        """Start the chunks where they run and return (an iterator yielding (chunk, run_chunk's
        output) as chunks finish, in any order; a function that cancels the chunks not yet
        started)."""
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
    """Every trial in this process, one after the other (`--workers 1`).

    Each chunk runs with numpy's BLAS held to one thread (`threadpoolctl`), as in the worker
    processes: a multi-threaded BLAS splits its sums differently and changes the last bits of
    a result, which a long filter run (Victoria Park) carries into its tables."""

    name = "serial"

    def _submit(self, fn, chunks):
        def run():
            for chunk in chunks:
                with _blas_controller().limit(limits=1, user_api="blas"):
                    out = run_chunk(fn, chunk)
                yield chunk, out

        return run(), lambda: None


_CONTROLLER = None


def _blas_controller():
    """The process's `threadpoolctl.ThreadpoolController` (made once: it scans the loaded
    libraries)."""
    global _CONTROLLER
    if _CONTROLLER is None:
        from threadpoolctl import ThreadpoolController

        _CONTROLLER = ThreadpoolController()
    return _CONTROLLER
