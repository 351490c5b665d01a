"""What every experiment receives, and the registry `trunkslam reproduce` runs from."""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = ["RunContext", "EXPERIMENTS", "get_experiment"]


@dataclass
class RunContext:
    """Settings shared by all experiments of one `trunkslam reproduce` call.

    out_dir: folder for tables (.md/.csv), figures (.png) and recordings (.rrd).
    quick: small-sample version (tests, smoke runs).
    seed: the root seed; experiments derive their generators with `rng(name)`.
    progress: callback(description, done, total) for long loops; no-op by default.
    config: the resolved parameters each experiment used, written to manifest.json.
    """

    out_dir: Path
    quick: bool = False
    seed: int = 0
    progress: Callable[[str, int, int], None] = lambda desc, done, total: None
    config: dict = field(default_factory=dict)
    outputs: list[Path] = field(default_factory=list)

    def rng(self, name: str) -> np.random.Generator:
        """A generator for one experiment, independent of the others and of their order."""
        key = [self.seed] + [ord(c) for c in name]
        return np.random.default_rng(np.random.SeedSequence(key))

    def path(self, name: str) -> Path:
        """Where to write output `name`; it is recorded in the manifest."""
        p = self.out_dir / name
        p.parent.mkdir(parents=True, exist_ok=True)
        self.outputs.append(p)
        return p


# name -> "module:function"; the function takes a RunContext. Order is the run order.
EXPERIMENTS: dict[str, str] = {
    "features": "experiments.exp_features:run",
    "table1": "experiments.exp_circles:run_tables",
    "table2": "experiments.exp_circles:run_tables",
    "circle-sweep": "experiments.exp_circles:run_sweep",
    "table3": "experiments.exp_slam:run_table3",
    "table4": "experiments.exp_slam:run_table4",
    "association": "experiments.exp_association:run",
}


def get_experiment(name: str) -> Callable[[RunContext], None]:
    try:
        target = EXPERIMENTS[name]
    except KeyError:
        known = ", ".join(EXPERIMENTS)
        raise ValueError(f"unknown experiment {name!r}; known: {known}") from None
    module, func = target.split(":")
    return getattr(importlib.import_module(module), func)
