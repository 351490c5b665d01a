"""`trunkslam bench smoother`: seconds of the GTSAM smoother's solvers.

Problems: one tree-park run (240 scans, `paper` features, IHGR), the Victoria Park full run
(7249 scans, published detections, IHGR, the ute preset) and GTSAM's own Victoria Park graph
(6969 poses, 151 landmarks). For our runs the EKF runs first and the smoother re-solves its log:
batch Levenberg-Marquardt from the EKF's estimate, iSAM2 fed scan by scan, iSAM2 then a batch
polish; the seconds exclude the marginal covariances (their time is a column of its own).
For GTSAM's graph: batch LM from the file's dead-reckoned values, iSAM2 one pose at a time and
in chunks of poses, each followed by a polish. One process; times by `time.perf_counter`.
"""

from __future__ import annotations

import numpy as np

from experiments.bench.slam import records_table
from experiments.errors import MissingDataError
from slam import run_slam
from slam.smoother import SmootherOptions, problem_from_log, smooth, solve_graph_file

__all__ = ["bench_smoother", "format_table"]

SOLVERS = {
    "batch": SmootherOptions(),
    "isam2": SmootherOptions(solver="isam2"),
    "isam2+polish": SmootherOptions(solver="isam2", polish=True),
}


def bench_smoother(
    root=None, chunks: tuple[int, ...] = (25,), per_pose: bool = True, seed: int = 0, progress=None
) -> list[dict]:
    """Rows {problem, solver, poses, landmarks, chi2 per dof, iterations, seconds, seconds
    marginals}; the Victoria Park rows are left out (and said, as a row) without the data."""
    from experiments.io.config_file import load_slam_config
    from experiments.io.victoria_park import gtsam_graph, load_victoria_park
    from experiments.sim.trajectory import simulate_cycab_run

    rows = []
    seq = simulate_cycab_run(np.random.default_rng(seed))
    rows += _our_run("tree park run", seq, "paper", None)
    _tick(progress, 1)
    try:
        vp = load_victoria_park(root, full=True)
    except MissingDataError as exc:
        rows.append({"problem": f"Victoria Park run: skipped ({exc})"})
    else:
        rows += _our_run(
            "Victoria Park run", vp, "detections", load_slam_config("victoria_park_ute")
        )
    _tick(progress, 2)
    try:
        graph = gtsam_graph(root)
    except MissingDataError as exc:
        rows.append({"problem": f"GTSAM victoria_park.txt: skipped ({exc})"})
        return rows
    runs = [("batch", 1)] + ([("isam2", 1)] if per_pose else [])
    runs += [("isam2-chunks", c) for c in chunks]
    for method, chunk in runs:
        g = solve_graph_file(graph, method, chunk)
        rows.append(
            {
                "problem": "GTSAM victoria_park.txt",
                "solver": g.method,
                "poses": g.n_poses,
                "landmarks": g.n_landmarks,
                "chi2 per dof": round(g.chi2_per_dof, 3),
                "iterations": g.iterations,
                "seconds": round(g.seconds, 2),
            }
        )
    _tick(progress, 3)
    return rows


def _our_run(label: str, seq, features: str, cfg) -> list[dict]:
    log = run_slam(seq, cfg, features=features, association="ihgr")
    problem = problem_from_log(log)
    rows = []
    for name, options in SOLVERS.items():
        r = smooth(problem, options)
        rows.append(
            {
                "problem": label,
                "solver": name,
                "poses": problem.n_scans,
                "landmarks": int(problem.landmark_id.size),
                "chi2 per dof": round(r.chi2_per_dof, 3),
                "iterations": r.iterations,
                "seconds": round(r.seconds, 2),
                "seconds marginals": round(r.seconds_marginals, 2),
            }
        )
    return rows


def _tick(progress, done: int) -> None:
    if progress is not None:
        progress("bench smoother", done, 3)


def format_table(rows: list[dict]) -> str:
    return records_table("GTSAM smoother seconds", rows)
