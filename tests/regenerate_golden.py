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

if __name__ == "__main__":  # as a script, tests/ is sys.path[0] and its folders shadow the packages
    here = Path(__file__).resolve().parent
    sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != here]

import numpy as np  # noqa: E402

from experiments.paper.circles import METHODS, TABLE_PILLARS, pillar_monte_carlo, summarise  # noqa: E402
from experiments.paper.runner import experiment_seed  # noqa: E402
from experiments.paper.slam import Exp2Config, key_figures, monte_carlo  # noqa: E402

GOLDEN = Path(__file__).resolve().parent / "golden"
FILES = {
    "circles": GOLDEN / "circles_quick.json",
    "slam": GOLDEN / "exp_slam_quick.json",
    "victoria_park": GOLDEN / "victoria_park_1000.json",
    "window_loop": GOLDEN / "window_loop.json",
}


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


def victoria_park_1000() -> dict:
    """The first 1000 scans of the full Victoria Park run (published detections, IHGR, preset
    victoria_park_ute): landmarks, GPS figures, NIS inside its bounds. Needs the data."""
    from experiments.eval.gps import score_sequence
    from experiments.io.config_file import load_slam_config
    from experiments.io.victoria_park import load_victoria_park
    from experiments.paper.victoria_park.real_run import nis_inside
    from slam import run_slam

    seq = load_victoria_park(full=True, n_scans=1000)
    cfg = load_slam_config("victoria_park_ute")
    lg = run_slam(seq, cfg, features="detections", association="ihgr")
    sc = score_sequence(seq, lg.scan_t, lg.pose, lg.antenna_pose)
    return {
        "landmarks": int(lg.landmark_xy.shape[0]),
        "rmse_m": round(sc.all_rmse, 4),
        "median_m": round(sc.all_median, 4),
        "rmse_aligned_m": round(sc.clean_rmse_aligned, 4),
        "nis_inside": round(float(np.mean(nis_inside(lg))), 4),
        "fixes": sc.matched,
        "jumps": sc.jumps,
        "_note": "written by `python tests/regenerate_golden.py victoria_park` after the preset "
        "changed; compared by tests/experiments/test_victoria_park.py",
    }


WINDOW_LOOP_METHODS = (("IHGR window K = 3", "ihgr-window", 3), ("IHGR (single scan)", "ihgr", 0))


def window_loop() -> dict:
    """The IHGR window in the SLAM loop (`experiments.paper.association_loop.tree_park_loop`):
    2 tree-park runs of 170 scans with the odometry noise x2, seed 0, the K = 3 window beside
    single-scan IHGR: landmarks, false pairings, duplicates, missed trees, pose error."""
    from experiments.paper.association_loop import tree_park_loop

    rows = tree_park_loop(
        np.random.default_rng(experiment_seed(0, "window_loop")),
        2,
        noise_scales=(2.0,),
        methods=WINDOW_LOOP_METHODS,
        n_scans=170,
    )
    keys = ("landmarks", "false_pairings", "updates", "duplicates", "missed_trees")
    out = {
        r["method"]: {
            **{k: r[k] for k in keys},
            "pose_error_m": round(r["pose_error_m"], 5),
            "window_fractional": r["window_fractional"],
        }
        for r in rows
    }
    out["_note"] = (
        "written by `python tests/regenerate_golden.py window_loop`; compared by "
        "tests/experiments/test_association_loop.py"
    )
    return out


COMPUTE = {
    "circles": circles_quick,
    "slam": slam_quick,
    "victoria_park": victoria_park_1000,
    "window_loop": window_loop,
}


def main(names: list[str]) -> None:
    for name in names or list(COMPUTE):
        if name not in COMPUTE:
            raise SystemExit(f"unknown golden file {name!r}; known: {list(COMPUTE)}")
        FILES[name].write_text(json.dumps(COMPUTE[name](), indent=1, sort_keys=True) + "\n")
        print(f"wrote {FILES[name]}")


if __name__ == "__main__":
    main(sys.argv[1:])
