"""The golden numbers in tests/golden/: how each is computed, and the script that rewrites them.

    python tests/regenerate_golden.py            # rewrite every golden file
    python tests/regenerate_golden.py circles    # one of them

Regenerate only after a deliberate change of method, and say so in the commit. The tests compare
the same computations (the functions below) with the files, at the tolerances they state.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from experiments.paper.circles import METHODS, TABLE_PILLARS, pillar_monte_carlo, summarise
from experiments.paper.runner import experiment_seed
from experiments.paper.slam import Exp2Config, key_figures, monte_carlo

GOLDEN = Path(__file__).resolve().parent / "golden"
FILES = {"circles": GOLDEN / "circles_quick.json", "slam": GOLDEN / "exp_slam_quick.json"}


def circles_quick() -> dict:
    """Experiment 1, quick (seed 0, 20 draws): mean CE, mean RE and miss rate of pillars d-g."""
    mc = pillar_monte_carlo(20, np.random.default_rng(experiment_seed(0, "table1")))
    s = summarise(mc)
    return {
        m: {p: {k: s[m][p].get(k) for k in ("ce_mean", "re_mean", "miss")} for p in TABLE_PILLARS}
        for m in METHODS
    }


def slam_rng() -> np.random.Generator:
    """The generator of the golden experiment-2 run (`RunContext(seed=0).rng("slam")`)."""
    return np.random.default_rng(experiment_seed(0, "slam"))


def slam_quick() -> dict:
    """Experiment 2, quick (`Exp2Config.quick()`, seed 0): Table 3 and 4 figures, NEES, NIS, map
    sizes per method."""
    figs = key_figures(monte_carlo(Exp2Config.quick(), slam_rng()))
    figs["_note"] = (
        "written by `python tests/regenerate_golden.py slam`: Exp2Config.quick(), seed 0; "
        "compared by tests/experiments/test_paper_slam.py"
    )
    return figs


COMPUTE = {"circles": circles_quick, "slam": slam_quick}


def main(names: list[str]) -> None:
    for name in names or list(COMPUTE):
        if name not in COMPUTE:
            raise SystemExit(f"unknown golden file {name!r}; known: {list(COMPUTE)}")
        FILES[name].write_text(json.dumps(COMPUTE[name](), indent=1, sort_keys=True) + "\n")
        print(f"wrote {FILES[name]}")


if __name__ == "__main__":
    main(sys.argv[1:])
