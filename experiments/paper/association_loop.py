"""The association methods inside the SLAM loop (the `association` experiment's second part).

Single-scan IHGR, the K-scan IHGR window (`slam.run_slam(association="ihgr-window")`, K = 2, 3, 4),
JCBB and NN, each running the whole EKF-SLAM loop, where the association's mistakes feed back
into the filter:

- the simulated tree park of experiment 2 (`experiments.paper.slam`: paper features, the
  default Cycab) with its odometry noise (the simulation's and the filter's) x1, x2 and x4:
  more pose uncertainty, wider gates;
- Victoria Park, the full run (7249 scans) with the published detections and the preset
  `victoria_park_ute` (when the data is there).

Figures per method (summed or averaged over the runs):
  false pairings   measurements used in an update whose true object is not the landmark's
                   (`experiments.eval.mapping.false_pairings`; per-beam truth labels; tree park)
  duplicates       extra landmarks within 1 m of one tree (tree park: the true trees; Victoria
                   Park: the 145 trees of the 2002 SLAM school's map of scans 1-2000, aligned by
                   the paths; a SLAM result, not surveyed truth)
  missed trees     trees detected in >= 3 scans (tree park) or reference trees (Victoria Park)
                   with no landmark within 1 m
  pose error       tree park: mean position error against the exact pose (m) and mean |dtheta|;
                   Victoria Park: RMSE of the GPS antenna point against the GPS fixes
  ms a scan        the filter alone (features extracted beforehand)
  window           share of window steps whose first LP was fractional, and of steps whose
                   rounding changed the LP's answer (more than one LP solve)
"""

from __future__ import annotations

import logging
import math
from dataclasses import replace

import numpy as np

from experiments.eval.detections import dominant_label, run_labels
from experiments.eval.gospa import gospa_columns
from experiments.eval.mapping import duplicates_and_missed, false_pairings
from experiments.eval.poses import pose_errors
from experiments.paper.slam import CYCAB_SLAM, extractor_params
from experiments.sim.trajectory import MONTE_CARLO_PATH, CycabParams, simulate_cycab_run
from features import extract_features
from slam import OdometryNoise, SlamConfig, interpolate_poses, run_slam, se2

__all__ = [
    "LOOP_LABELS",
    "LOOP_METHODS",
    "loop_records",
    "tree_park_loop",
    "tree_park_trial",
    "victoria_park_batch",
    "victoria_park_loop",
    "victoria_park_trial",
]

log = logging.getLogger(__name__)

# (label, association, window K)
LOOP_METHODS = (
    ("IHGR (single scan)", "ihgr", 0),
    ("IHGR window K = 2", "ihgr-window", 2),
    ("IHGR window K = 3", "ihgr-window", 3),
    ("IHGR window K = 4", "ihgr-window", 4),
    ("JCBB", "jcbb", 0),
    ("NN", "nn", 0),
)
NOISE_SCALES = (1.0, 2.0, 4.0)
TREE_PARK_RUNS = 20
TOL_M = 1.0  # a landmark within this of a tree stands for it
# the map's GOSPA against all the park's trees (p = 2, alpha = 2), mean over the runs
LOOP_GOSPA = ("gospa_1m", "gospa_20m")
SEEN_SCANS = 3  # a tree detected in this many scans could have been mapped


def _config(base: SlamConfig, association: str, K: int) -> SlamConfig:
    """`base` with the association method (and the window's K when given; a window of K scans
    confirms a new landmark after at most K sightings, so confirm_scans is min(its, K): what the
    filter does anyway, said in the configuration rather than warned about at every run)."""
    changes = {"association.method": association}
    if K:
        changes["association.window_scans"] = K
        changes["map_policy.confirm_scans"] = min(base.map_policy.confirm_scans, K)
    return base.with_(**changes)


def _window_figures(stats: dict | None) -> dict:
    if not stats:
        return {"window_steps": 0, "window_fractional": 0, "window_rounded": 0}
    return {
        "window_steps": stats["steps"],
        "window_fractional": stats["fractional_lps"],
        "window_rounded": stats["rounded_steps"],
    }


def tree_park_loop(
    rng: np.random.Generator,
    n_runs: int,
    noise_scales=NOISE_SCALES,
    methods=LOOP_METHODS,
    n_scans: int | None = None,
    progress=lambda desc, done, total: None,
    executor=None,
) -> list[dict]:
    """Per (noise scale, method): summed and averaged figures over n_runs simulated runs (run i
    of every scale and method uses the same seed: common random numbers). Each (scale, run) is
    a trial (`tree_park_trial`) on `executor` (default: this process), reduced in order."""
    from experiments.exec.trials import SerialExecutor

    seeds = [int(v) for v in rng.integers(0, 2**63 - 1, n_runs)]
    jobs = [(scale, n_scans, tuple(methods)) for scale in noise_scales for _ in range(n_runs)]
    records = (executor or SerialExecutor()).map(
        tree_park_trial,
        jobs,
        seeds * len(noise_scales),
        desc="association in the loop (tree park)",
        progress=progress,
        chunksize=1,
    )
    rows = []
    for i, scale in enumerate(noise_scales):
        runs = records[i * n_runs : (i + 1) * n_runs]
        for label, _, _ in methods:
            a = [run[label] for run in runs]
            rows.append(
                {
                    "data": f"tree park, odometry noise x{scale:g}",
                    "method": label,
                    "runs": n_runs,
                    "landmarks": float(np.mean([r["landmarks"] for r in a])),
                    "false_pairings": int(sum(r["false"] for r in a)),
                    "updates": int(sum(r["used"] for r in a)),
                    "duplicates": int(sum(r["duplicates"] for r in a)),
                    "missed_trees": int(sum(r["missed"] for r in a)),
                    "pose_error_m": float(np.mean([r["pos_err"] for r in a])),
                    "worst_pose_error_m": float(np.max([r["max_pos_err"] for r in a])),
                    "dtheta_rad": float(np.mean([r["dtheta"] for r in a])),
                    "gps_rmse_m": math.nan,
                    "gps_vouched_rmse_m": math.nan,
                    "ms_per_scan": float(np.mean([r["ms"] for r in a])),
                    "window_steps": int(sum(r["window_steps"] for r in a)),
                    "window_fractional": int(sum(r["window_fractional"] for r in a)),
                    "window_rounded": int(sum(r["window_rounded"] for r in a)),
                    **{k: float(np.mean([r[k] for r in a])) for k in LOOP_GOSPA},
                }
            )
    return rows


def tree_park_trial(job: tuple, seed: int) -> dict:
    """One simulated tree-park run (`job` = (odometry noise scale, scans or None, methods)) with
    every method on it: method label -> its figures. A pure function of (job, seed)."""
    scale, n_scans, methods = job
    base_cyc = CycabParams(**MONTE_CARLO_PATH)
    if n_scans is not None:
        base_cyc = replace(base_cyc, n_scans=n_scans)
    cyc = replace(
        base_cyc,
        speed_sigma_mps=base_cyc.speed_sigma_mps * scale,
        steer_sigma_rad=base_cyc.steer_sigma_rad * scale,
    )
    # the simulated Cycab's filter (`CYCAB_SLAM`) with its odometry noise as simulated, with the
    # built-in pose floor (`OdometryNoise`'s); paper's circles
    params = extractor_params("paper", cyc)
    base = CYCAB_SLAM.with_(
        **{
            "vehicle.odometry_noise": OdometryNoise(cyc.speed_sigma_mps, cyc.steer_sigma_rad),
            "features.method": "paper",
            **{f"features.extractor.{k}": v for k, v in params.items()},
        }
    )
    seq = simulate_cycab_run(np.random.default_rng(seed), "tree_park", cyc)
    truth = interpolate_poses(seq.scan_t, seq.truth_t, seq.truth_pose)
    params, options = base.features.extractor_args()
    feats = [extract_features(seq.scan(k), "paper", params, **options) for k in range(seq.n_scans)]
    objects = [
        [
            dominant_label(run_labels(seq.scan_labels[k], a, b), returns_only=True)[0]
            for a, b in f.circle_beams
        ]
        for k, f in enumerate(feats)
    ]
    trees = seq.truth_landmarks
    seen_count = np.zeros(trees.shape[0], np.int64)
    for obj in objects:
        for o in set(obj):
            if 0 <= o < trees.shape[0]:
                seen_count[o] += 1
    seen = seen_count >= SEEN_SCANS
    out = {}
    for label, assoc, K in methods:
        lg = run_slam(seq, _config(base, assoc, K), features=feats)
        e = pose_errors(lg.pose, truth)[1:]
        false, used = false_pairings(lg, lambda k, i, o=objects: o[k][i])
        dup, missed = duplicates_and_missed(lg.landmark_xy, trees[:, :2], seen, TOL_M)
        out[label] = {
            "false": false,
            "used": used,
            "landmarks": lg.landmark_xy.shape[0],
            "duplicates": dup,
            "missed": missed,
            "pos_err": float(np.mean(np.hypot(e[:, 0], e[:, 1]))),
            "max_pos_err": float(np.max(np.hypot(e[:, 0], e[:, 1]))),
            "dtheta": float(np.mean(np.abs(e[:, 2]))),
            "ms": 1e3 * float(np.mean(lg.timing_s["total"])),  # the filter's, after warm-up
            **_window_figures(lg.window_stats),
            **{
                k: v
                for k, v in gospa_columns(lg.landmark_xy, trees[:, :2]).items()
                if k in LOOP_GOSPA
            },
        }
    return out


def victoria_park_loop(
    n_scans: int | None = None,
    methods=LOOP_METHODS,
    progress=lambda desc, done, total: None,
    executor=None,
) -> list[dict]:
    """The full Victoria Park run (or its first n_scans) with the published detections and the
    preset `victoria_park_ute`, one row per method, each a trial (`victoria_park_trial`) on
    `executor`. Raises MissingDataError without the data."""
    return victoria_park_batch(n_scans, methods, executor).result(progress)


def victoria_park_batch(n_scans: int | None = None, methods=LOOP_METHODS, executor=None):
    """`victoria_park_loop`'s trials handed to `executor` without waiting for them: their
    `experiments.exec.Batch`. Raises MissingDataError without the data, before any trial."""
    from experiments.exec.trials import SerialExecutor
    from experiments.io.victoria_park import load_ss2002_reference, load_victoria_park

    load_victoria_park(full=True)  # missing or corrupt data: said here, before any trial
    load_ss2002_reference()
    return (executor or SerialExecutor()).submit(
        victoria_park_trial,
        [(n_scans, m) for m in methods],
        desc="association in the loop (Victoria Park)",
        chunksize=1,
    )


def victoria_park_trial(job: tuple, seed=None) -> dict:
    """One method (`job` = (scans or None, (label, association, K))) on the Victoria Park run:
    its row. Deterministic (the seed is unused)."""
    from experiments.eval.gps import score_sequence
    from experiments.eval.map_quality import reference_in_our_frame
    from experiments.eval.vouched import vouched_for_sequence
    from experiments.io.config_file import load_slam_config
    from experiments.io.victoria_park import load_ss2002_reference, load_victoria_park
    from experiments.paper.victoria_park.real_run import PRESET, head

    n_scans, (label, assoc, K) = job
    full = load_victoria_park(full=True)
    ground, ref_trees = load_ss2002_reference()
    if n_scans is not None:
        full = head(full, n_scans)
    cfg = load_slam_config(PRESET)
    lg = run_slam(full, _config(cfg.with_(**{"features.method": "detections"}), assoc, K))
    vouched = vouched_for_sequence(full, cfg)
    sc = score_sequence(full, lg.scan_t, lg.pose, lg.antenna_pose, vouched)
    n = min(ground.shape[0], lg.n_scans)
    ours = np.array([se2.compose(p, lg.laser_pose)[:2] for p in lg.pose[:n]])
    tw = reference_in_our_frame(ours, ground, ref_trees)
    dup, missed = duplicates_and_missed(lg.landmark_xy, tw, None, TOL_M)
    return {
        "data": f"Victoria Park, {lg.n_scans} scans, published detections",
        "method": label,
        "runs": 1,
        "landmarks": float(lg.landmark_xy.shape[0]),
        "false_pairings": -1,
        "updates": int(lg.obs_scan.size),
        "duplicates": dup,
        "missed_trees": missed,
        "pose_error_m": math.nan,
        "worst_pose_error_m": math.nan,
        "dtheta_rad": math.nan,
        "gps_rmse_m": float(sc.all_rmse),
        "gps_vouched_rmse_m": float(sc.vouched_rmse),
        "ms_per_scan": 1e3 * float(np.mean(lg.timing_s["total"])),
        **_window_figures(lg.window_stats),
        **dict.fromkeys(LOOP_GOSPA, math.nan),  # scans 1-2000: the Victoria Park table's
    }


LOOP_LABELS = {
    "false_pairings": "false pairings",
    "missed_trees": "missed trees",
    "pose_error_m": "pose error (m)",
    "worst_pose_error_m": "worst pose error (m)",
    "dtheta_rad": "dtheta (rad)",
    "gps_rmse_m": "GPS RMSE (m)",
    "gps_vouched_rmse_m": "GPS RMSE, vouched fixes (m)",
    "ms_per_scan": "ms per scan",
    "window_lps_fractional": "window LPs fractional",
    "window_steps_rounded": "window steps rounded",
    "window_steps": "window steps",
    "gospa_1m": "GOSPA c = 1 m (m)",
    "gospa_20m": "GOSPA c = 20 m (m)",
}


NOTES = (
    "Every method runs the whole EKF-SLAM loop (`slam.run_slam`); its mistakes feed back into the "
    "filter. Tree park: experiment 2's simulated runs (paper features, 240 scans) with the "
    "odometry noise of the simulation and of the filter scaled x1, x2, x4; run i of every row "
    "uses the same seed. Victoria Park: the full run with the published detections and the "
    "preset victoria_park_ute.\n\n"
    "- false pairings: measurements used in an update whose true object (per-beam labels) is not "
    "the object most of its landmark's measurements came from; summed over the runs, out of "
    "'updates'. n/a on Victoria Park (no per-detection truth).\n"
    "- duplicates: extra landmarks within 1 m of one tree (Victoria Park: of one of the 145 trees "
    "of the 2002 SLAM school's map of scans 1-2000, aligned by the paths); missed trees: trees "
    "detected in >= 3 scans (Victoria Park: reference trees) with no landmark within 1 m; "
    "summed over the runs.\n"
    "- pose error: mean over runs and scans of the position error against the exact pose; "
    "worst: the largest over every scan of every run; GPS RMSE: the antenna point against the "
    "GPS fixes (`experiments.eval.gps`); vouched fixes: only those the run's odometry, "
    "dead-reckoned, vouches for (`experiments.eval.vouched`).\n"
    "- ms per scan: the filter alone, wall time on the machine that wrote this file.\n"
    "- IHGR window: `slam.run_slam(association='ihgr-window')`, K = 2, 3, 4; a new landmark needs "
    "min(3, K) sightings in the window. 'window LPs fractional': window steps whose first LP "
    "relaxation was fractional, out of all steps; 'window steps rounded': steps where the "
    "rounding changed the LP's answer (more than one LP solve).\n"
    "- GOSPA (p = 2, alpha = 2; experiments/eval/gospa.py): the final map against all the "
    "park's trees, c = 1 m and the RFS-SLAM papers' c = 20 m, mean over the runs; empty on "
    "Victoria Park (the full run's map is scored on scans 1-2000 in the Victoria Park table).\n"
)


def loop_records(rows: list[dict]) -> list[dict]:
    """The in-the-loop table's records: one per data set and method (false pairings empty on
    Victoria Park, the window counts empty for the single-scan methods)."""
    out = []
    for r in rows:
        steps = r["window_steps"]
        out.append(
            {
                "data": r["data"],
                "method": r["method"],
                "runs": r["runs"],
                "landmarks": r["landmarks"],
                "false_pairings": None if r["false_pairings"] < 0 else r["false_pairings"],
                "updates": r["updates"],
                "duplicates": r["duplicates"],
                "missed_trees": r["missed_trees"],
                "pose_error_m": r["pose_error_m"],
                "worst_pose_error_m": r["worst_pose_error_m"],
                "dtheta_rad": r["dtheta_rad"],
                "gps_rmse_m": r["gps_rmse_m"],
                "gps_vouched_rmse_m": r["gps_vouched_rmse_m"],
                "ms_per_scan": r["ms_per_scan"],
                "window_lps_fractional": r["window_fractional"] if steps else None,
                "window_steps_rounded": r["window_rounded"] if steps else None,
                "window_steps": steps or None,
                **{k: r[k] for k in LOOP_GOSPA},
            }
        )
    return out
