"""What every experiment receives, and the experiments `trunkslam reproduce` runs (registered
by each experiment: `experiments.paper.registry`)."""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from experiments.errors import ConfigError
from experiments.exec import Batch, Executor, SerialExecutor
from experiments.paper.registry import REGISTERED, Experiment, declared

__all__ = [
    "DEFAULT_EXPERIMENTS",
    "EXPERIMENTS",
    "Experiment",
    "RunContext",
    "experiment_seed",
    "get_experiment",
]


@dataclass
class RunContext:
    """Settings shared by all experiments of one `trunkslam reproduce` call.

    out_dir: folder for tables (.md/.csv), figures (.png) and recordings (.rrd).
    quick: small-sample version (tests, smoke runs).
    seed: the root seed; experiments derive their generators with `rng(name)`.
    progress: callback(description, done, total) for long loops; no-op by default.
    config: the resolved parameters each experiment used, written to manifest.json.
    executor: where the experiments' trials run (`experiments.exec`; default: this process).
    deferred: (batch, finish) pairs handed over by `later`, finished by `run_experiments` after
        every experiment has started.
    """

    out_dir: Path
    quick: bool = False
    seed: int = 0
    progress: Callable[[str, int, int], None] = lambda desc, done, total: None
    config: dict = field(default_factory=dict)
    outputs: list[Path] = field(default_factory=list)
    executor: Executor = field(default_factory=SerialExecutor)
    deferred: list[tuple[Batch, Callable[[list], None]]] = field(default_factory=list)

    def map(self, fn, configs, seeds=None, desc: str = "trials", chunksize=None) -> list:
        """The records of trials `fn(configs[i], seeds[i])`, in order, run on `executor` with
        progress (`Executor.map`)."""
        return self.executor.map(
            fn, configs, seeds, desc=desc, progress=self.progress, chunksize=chunksize
        )

    def submit(self, fn, configs, seeds=None, desc: str = "trials", chunksize=None) -> Batch:
        """The trials of `map`, handed to `executor` without waiting (`Executor.submit`): this
        process goes on while the workers run them; `result(ctx.progress)` waits for them."""
        return self.executor.submit(fn, configs, seeds, desc=desc, chunksize=chunksize)

    def later(self, batch: Batch, finish: Callable[[list], None]) -> None:
        """Finish part of the running experiment after the others: once every experiment of the
        run has started, `run_experiments` calls `finish(batch's records)` (which writes the
        outputs made from them, as the experiment would have). Meanwhile the batch's trials run
        beside the next experiments' trials, on workers that would otherwise wait. An error in
        the batch or in `finish` fails this experiment as an error in its body does."""
        self.deferred.append((batch, finish))

    def finish(self) -> None:
        """Finish the deferred parts now, in the order handed over (waiting for their trials):
        for a caller that runs an experiment by itself; `run_experiments` does this after all
        of its experiments."""
        while self.deferred:
            batch, finish = self.deferred.pop(0)
            finish(batch.result(self.progress))

    def rng(self, name: str) -> np.random.Generator:
        """A generator for one experiment, independent of the others and of their order."""
        return np.random.default_rng(experiment_seed(self.seed, name))

    def path(self, name: str) -> Path:
        """Where to write output `name`; it is recorded in the manifest."""
        p = self.out_dir / name
        p.parent.mkdir(parents=True, exist_ok=True)
        self.outputs.append(p)
        return p


def experiment_seed(seed: int, name: str) -> np.random.SeedSequence:
    """The seed sequence of experiment `name` under root seed `seed`."""
    return np.random.SeedSequence([seed] + [ord(c) for c in name])


# Order is the run order: each experiment's `order` (`experiments.paper.registry`).
EXPERIMENTS: dict[str, Experiment] = declared()
DEFAULT_EXPERIMENTS = tuple(name for name, e in EXPERIMENTS.items() if e.default)


def get_experiment(name: str) -> Callable[[RunContext], None]:
    """The function of experiment `name`, its module imported (and its registration checked
    against the declaration read from the source)."""
    try:
        target = EXPERIMENTS[name].target
    except KeyError:
        known = ", ".join(EXPERIMENTS)
        raise ConfigError(f"unknown experiment {name!r}; known: {known}") from None
    module, func = target.split(":")
    fn = getattr(importlib.import_module(module), func)
    if REGISTERED.get(name) != EXPERIMENTS[name]:  # a decorator the source reading misread
        raise RuntimeError(
            f"experiment {name!r}: registered {REGISTERED.get(name)}, read {EXPERIMENTS[name]}"
        )
    return fn
