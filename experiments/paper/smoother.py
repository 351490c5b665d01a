"""Experiment `smoother`: the GTSAM smoother (`slam.smoother`) as the reference for the EKF.

1. GTSAM's own Victoria Park graph (`victoria_park/gtsam/victoria_park.txt`, 6969 poses, 151
   landmarks, associations given): the counts GTSAM's unit test expects, and a solve to the
   global optimum: iSAM2 fed `GRAPH_CHUNK` poses per update (each new pose started from the
   previous estimate composed with its odometry, each landmark from its first measurement),
   then a batch Levenberg-Marquardt polish. Batch LM from the file's dead-reckoned values and
   iSAM2 one pose at a time are timed by `trunkslam bench smoother`.
2. The Victoria Park full run (published detections, IHGR, the ute preset): the EKF, then the
   batch smoother of that run (same odometry, measurements and associations, started from the
   EKF's path and map), both scored against GPS as the `victoria-park` experiment does.
3. The same with loop closure on (`[closure] enabled`): the smoother then has the closure's
   re-associated measurements (the merged landmarks' measurements under the kept ids).
The tree park's smoother figures (EKF against smoother, same runs) are columns of table3 and
consistency (experiment `table3`).

Writes smoother.md/.csv, vp_smoother_map.png (EKF and smoother paths over the GPS track, with
the smoothed map) and vp_smoother_errors.png (their distance to the GPS fixes against time).
Parts whose data is absent are skipped with a note in the manifest; corrupt data (a sha256 that
differs) fails the experiment. --quick: the first 1500
scans of the full run.
"""

from __future__ import annotations

import logging
import time

import numpy as np

from experiments.errors import MissingDataError
from experiments.eval.gps import score_sequence
from experiments.eval.vouched import vouched_for_sequence
from experiments.io.config_file import load_slam_config
from experiments.io.victoria_park import gtsam_graph, load_victoria_park
from experiments.io.writers import write_tidy_table
from experiments.paper import products
from experiments.paper.registry import experiment
from slam import run_slam, se2
from slam.smoother import problem_from_log, smooth, solve_graph_file

__all__ = ["GRAPH_CHUNK", "run", "smoother_trial"]

log = logging.getLogger(__name__)

# poses per iSAM2 update on GTSAM's graph (the sweep on docs/experiments/smoother.md)
GRAPH_CHUNK = 25
PRESET = "victoria_park_ute"
LABELS = {  # the table's fields and their Markdown headers
    "problem": "problem",
    "solver": "solver",
    "poses": "poses",
    "landmarks": "landmarks",
    "chi2_per_dof": "chi2 per dof",
    "rmse_m": "RMSE vs GPS (m)",
    "median_m": "median (m)",
    "rmse_clean_m": "RMSE without jumps (m)",
    "rmse_aligned_m": "RMSE aligned (m)",
    "rmse_vouched_m": "RMSE on vouched fixes (m)",
    "rmse_rfs_m": "RMSE, fixes within 25 ms of a scan (m)",
    "landmark_sigma_median_m": "landmark sigma median (m)",
    "iterations": "iterations",
    "seconds": "seconds",
}


def smoother_trial(job: tuple, seed=None) -> dict:
    """One part of the experiment, a deterministic trial (seed None): ("graph", None) solves
    GTSAM's graph file (found where this process looks for the data); ("victoria-park", quick)
    runs the EKF over the full run (--quick: 1500 scans) and smooths it;
    ("victoria-park-closure", quick) the same with loop closure on. Returns the table rows
    and, for the run without closure, its figures as files ({file name: PNG bytes})."""
    kind, arg = job
    if kind == "graph":
        g = solve_graph_file(gtsam_graph(), "isam2-chunks", GRAPH_CHUNK)
        row = {
            "problem": "GTSAM victoria_park.txt",
            "solver": g.method,
            "poses": g.n_poses,
            "landmarks": g.n_landmarks,
            "chi2_per_dof": float(g.chi2_per_dof),
            "iterations": g.iterations,
            "seconds": float(g.seconds),
        }
        return {"rows": [row], "method": g.method}
    return _victoria_park(arg, closure=kind == "victoria-park-closure")


@experiment(
    "smoother",
    order=80,
    page="smoother.md",
    help="GTSAM's Victoria Park graph solved; the full run's EKF against its smoother",
)
def run(ctx) -> None:
    """The registered experiment `smoother`: its parts are trials (`smoother_trial`), the run
    without closure also drawing the figures; the table is written after the other experiments have
    started (`RunContext.later`): the two parts, of unequal length, share the workers with the
    next experiments' trials."""
    cfg_out = ctx.config.setdefault("smoother", {})
    jobs = []
    try:
        graph = gtsam_graph()
        jobs.append(("graph", None))
    except MissingDataError as exc:
        log.warning("smoother: GTSAM's graph skipped: %s", exc)
        cfg_out["gtsam_graph"] = f"skipped: {exc}"
    try:
        load_victoria_park(full=True)
    except MissingDataError as exc:
        log.warning("smoother: the Victoria Park runs skipped: %s", exc)
        cfg_out["victoria_park"] = cfg_out["victoria_park_closure"] = f"skipped: {exc}"
    else:
        jobs += [("victoria-park", ctx.quick), ("victoria-park-closure", ctx.quick)]
    if not jobs:
        return
    # the longer part (the Victoria Park run) first, the graph beside it
    jobs.sort(key=lambda job: job[0] == "graph")
    batch = ctx.submit(smoother_trial, jobs, desc="smoother", chunksize=1)

    def finish(got_all: list) -> None:
        rows: list[dict] = []  # the graph's row first, as the table has always had it
        for (kind, _), got in sorted(zip(jobs, got_all), key=lambda jg: jg[0][0] != "graph"):
            rows += got["rows"]
            if kind == "graph":
                cfg_out["gtsam_graph"] = {"file": str(graph), "method": got["method"]}
                continue
            key = kind.replace("-", "_")
            cfg_out[key] = {"preset": PRESET, "scans": got["n"], "closure": kind != "victoria-park"}
            products.write(ctx, got["files"])
        notes = (
            "chi2 per dof: twice GTSAM's graph error over residuals minus unknowns. GTSAM's "
            f"graph: iSAM2 fed {GRAPH_CHUNK} poses per update, then batch Levenberg-Marquardt "
            "(the file's counts checked against GTSAM's unit test: 10,608 factors, 7,120 "
            "values). Victoria Park run: published detections, IHGR, "
            "the victoria_park_ute preset, loop closure off and on; the smoother has the EKF's "
            "odometry, measurements and associations (with closure, the merged landmarks' "
            "measurements under the kept ids) and starts from its path and map; scored against "
            "GPS at the antenna as in victoria_park.md; the vouched fixes are those the run's "
            "own odometry, dead-reckoned, vouches for (experiments/eval/vouched.py). Landmark "
            "sigma: the square root of the largest eigenvalue of each landmark's marginal "
            "covariance."
        )
        title = "The GTSAM smoother against the EKF"
        ctx.outputs += write_tidy_table(
            ctx.out_dir / "smoother",
            [{k: r.get(k) for k in LABELS} for r in rows],
            index=["problem", "solver"],
            values=list(LABELS)[2:],
            labels=LABELS,
            title=title,
            notes=notes,
        )

    ctx.later(batch, finish)


def _victoria_park(quick: bool, closure: bool = False) -> dict:
    from experiments.paper.victoria_park import figures
    from experiments.paper.victoria_park.real_run import GPS_GAP_S, head

    full = load_victoria_park(full=True)
    cfg = load_slam_config(PRESET)
    n = 1500 if quick else full.n_scans
    full = head(full, n)
    t0 = time.perf_counter()
    cfg = cfg.with_(**{"features.method": "detections", "closure.enabled": closure})
    lg = run_slam(full, cfg)
    ekf_s = time.perf_counter() - t0
    sm = smooth(problem_from_log(lg))
    vouched = vouched_for_sequence(full, cfg)
    sc_e = score_sequence(full, lg.scan_t, lg.pose, lg.antenna_pose, vouched=vouched)
    sc_s = score_sequence(full, lg.scan_t, sm.pose, lg.antenna_pose, vouched=vouched)
    sig = np.sqrt(np.linalg.eigvalsh(sm.landmark_cov)[:, -1])
    sig_e = np.sqrt(np.linalg.eigvalsh(lg.landmark_cov)[:, -1])
    label = f"Victoria Park, {n} scans" + (", loop closure" if closure else "")
    rows = [
        {
            "problem": label,
            "solver": "EKF",
            "poses": n,
            "landmarks": lg.landmark_id.size,
            **_gps(sc_e),
            "landmark_sigma_median_m": float(np.median(sig_e)),
            "seconds": ekf_s,
        },
        {
            "problem": label,
            "solver": f"smoother ({sm.solver})",
            "poses": n,
            "landmarks": sm.landmark_id.size,
            "chi2_per_dof": float(sm.chi2_per_dof),
            **_gps(sc_s),
            "landmark_sigma_median_m": float(np.median(sig)),
            "iterations": sm.iterations,
            "seconds": float(sm.seconds),
        },
    ]
    if closure:  # the figures are of the run without closure
        return {"rows": rows, "n": n, "files": {}}
    ant = {
        "EKF": np.array([se2.compose(p, lg.antenna_pose)[:2] for p in lg.pose]),
        "smoother": np.array([se2.compose(p, lg.antenna_pose)[:2] for p in sm.pose]),
    }
    errors = {"EKF": (sc_e.t_s, sc_e.errors), "smoother": (sc_s.t_s, sc_s.errors)}
    title = "Victoria Park: EKF and smoothed antenna paths over the GPS fixes (smoothed map)"
    files = {
        "vp_smoother_map.png": products.png(
            figures.plot_vp_map, full.gps_xy, ant, sm.landmark_xy, title
        ),
        "vp_smoother_errors.png": products.png(
            figures.plot_gps_errors,
            errors,
            sc_e.jump,
            "Victoria Park: distance to the GPS fixes (jumps marked x)",
            gap_s=GPS_GAP_S,
        ),
    }
    return {"rows": rows, "n": n, "files": files}


def _gps(sc) -> dict:
    return {
        "rmse_m": float(sc.all_rmse),
        "median_m": float(sc.all_median),
        "rmse_clean_m": float(sc.clean_rmse),
        "rmse_aligned_m": float(sc.all_rmse_aligned),
        "rmse_vouched_m": float(sc.vouched_rmse),
        "rmse_rfs_m": float(sc.rfs_rmse),
    }
