"""What every experiment receives, and the registry `trunkslam reproduce` runs from."""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from experiments.errors import ConfigError
from experiments.exec import Batch, Executor, SerialExecutor

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


@dataclass(frozen=True)
class Experiment:
    """A registered experiment: its function ("module:function", called with a RunContext),
    what it shows, and whether `trunkslam reproduce` without names runs it. Names that share a
    function (table1 and table2, table3 and table4) are one run."""

    target: str
    about: str = ""
    default: bool = True


# Order is the run order.
EXPERIMENTS: dict[str, Experiment] = {
    "features": Experiment(
        "experiments.paper.features:run", about="trunk classification; a Victoria Park scan"
    ),
    "table1": Experiment("experiments.paper.circles:run_tables", about="circle-centre error CE"),
    "table2": Experiment("experiments.paper.circles:run_tables", about="radius error RE"),
    "circle-sweep": Experiment(
        "experiments.paper.circles:run_sweep", about="CE, RE against range, radius, noise"
    ),
    "table3": Experiment("experiments.paper.slam:run", about="EKF-SLAM pose errors"),
    "table4": Experiment("experiments.paper.slam:run", about="false-detection rates"),
    "association": Experiment(
        "experiments.paper.association:run", about="IHGR, JCBB and NN: rates and optimality"
    ),
    "victoria-park": Experiment(
        "experiments.paper.victoria_park:run",
        about="EKF-SLAM on the real run against GPS (needs the data; skipped without)",
    ),
    "victoria-park-rfs": Experiment(
        "experiments.paper.victoria_park_rfs:run",
        about="the full run under the published RFS protocol, exactly: 100 clutter draws "
        "(needs the data; --quick: 10 draws; only when named)",
        default=False,
    ),
    "smoother": Experiment(
        "experiments.paper.smoother:run",
        about="GTSAM smoother: GTSAM's Victoria Park graph; the EKF's full run re-solved",
    ),
    "noise-calibration": Experiment(
        "experiments.paper.calibration:run", about="fit of the constant measurement-noise model"
    ),
    "victoria-park-calibration": Experiment(
        "experiments.paper.vp_calibration:run",
        about="the ute's noise and laser yaw from scans 1-2000 (not in the default run)",
        default=False,
    ),
    "victoria-park-map-policy": Experiment(
        "experiments.paper.vp_map_policy:run",
        about="the map policy's confirm_scans and pruning settings from scans 1-2000 (only when "
        "named)",
        default=False,
    ),
    "loop-closure": Experiment(
        "experiments.paper.loop_closure:run",
        about="simulated loops in a park and an orchard, loop closure off and on (only when named)",
        default=False,
    ),
    "sim-clutter": Experiment(
        "experiments.paper.sim_clutter:run",
        about="the map by object class in a simulated park with posts, cars, bushes and people "
        "(only when named)",
        default=False,
    ),
    "victoria-park-split-half": Experiment(
        "experiments.paper.vp_split_half:run",
        about="Victoria Park map figures judged on a half of scans 1-2000 no setting saw (needs "
        "the data; only when named)",
        default=False,
    ),
}
DEFAULT_EXPERIMENTS = tuple(name for name, e in EXPERIMENTS.items() if e.default)


def get_experiment(name: str) -> Callable[[RunContext], None]:
    try:
        target = EXPERIMENTS[name].target
    except KeyError:
        known = ", ".join(EXPERIMENTS)
        raise ConfigError(f"unknown experiment {name!r}; known: {known}") from None
    module, func = target.split(":")
    return getattr(importlib.import_module(module), func)
