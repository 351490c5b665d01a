"""Experiment `loop-closure`: simulated loops with known truth, loop closure off and on.

Each run drives once around `experiments.sim.loops.loop_scene` (a stand of trees, then open
ground long enough for the odometry to drift, then back into the stand) and the filter runs
on it with `[closure] enabled` false and true (`slam.closure`), each with the standard
Jacobians (the Cycab preset's filter, as in every other simulated experiment) and with
first-estimates Jacobians (`[filter] first_estimates_jacobians`, the Victoria Park preset's).
The filter models the odometry noise as simulated (`loop_config`), with the paper-faithful
extractor. Kinds: "park" (trees at random) and "orchard" (rows of identical trees on a grid,
where a closure onto the wrong trees is easy).

Per run and filter (`loop_trial`): the drift at the return (the filter's position error at the
first scan back in the stand, with closure off: what the per-scan gate must bridge), the
closures accepted and their pairs checked against the truth (a pair is right when both
landmarks' measurements hit the same simulated tree; a closure with any wrong pair is a false
closure), the map's size and duplicates (final landmarks whose measurements hit the same tree),
the final position error and the share of scans after the return whose pose NEES is inside its
95% bounds.
"""

from __future__ import annotations

import logging
import math

import numpy as np
from scipy.stats import chi2

from experiments.eval.series import slam_panels, slam_series
from experiments.paper import loop_closure_figures, products
from experiments.paper.products import TableSpec
from experiments.paper.registry import experiment
from experiments.paper.slam import CYCAB_SLAM, extractor_params
from experiments.sim.loops import loop_drive, loop_params
from features import extract_features
from slam import SlamConfig, interpolate_poses, run_slam, se2

__all__ = [
    "JACOBIANS",
    "RUNS",
    "closure_products",
    "drive_features",
    "loop_config",
    "loop_trial",
    "run",
]

log = logging.getLogger(__name__)

RUNS = {"park": 100, "orchard": 100}
QUICK_RUNS = 2  # of each kind, with --quick
NOISE_SCALE = 0.5  # of the Cycab's odometry noise: returns drift 0-8 m (module doc)
HOME_X_M = -15.0  # the stand starts here on the way back (`loop_scene`'s route)
# the filters compared (table column "jacobians"): name -> first_estimates_jacobians
JACOBIANS = {"standard": False, "first estimates": True}


def loop_config(
    closure: bool, noise_scale: float = NOISE_SCALE, first_estimates: bool = False
) -> SlamConfig:
    """Experiment 2's filter (`CYCAB_SLAM`, paper-faithful extractor; standard Jacobians
    unless `first_estimates`) with the odometry noise of `loop_drive` and loop closure on or
    off."""
    params = extractor_params("paper", loop_params(noise_scale))
    return CYCAB_SLAM.with_(
        **{
            "features.method": "paper",
            **{f"features.extractor.{k}": v for k, v in params.items()},
            "filter.first_estimates_jacobians": first_estimates,
            "vehicle.odometry_noise.speed_sigma_mps": 0.1 * noise_scale,
            "vehicle.odometry_noise.steer_sigma_rad": math.radians(2.0) * noise_scale,
            "closure.enabled": closure,
        }
    )


def drive_features(seed: int, kind: str) -> tuple:
    """(sequence, its paper-faithful features per scan) of `loop_drive(seed, kind)`."""
    seq = loop_drive(seed, kind, NOISE_SCALE)
    params, options = loop_config(False).features.extractor_args()
    return seq, [
        extract_features(seq.scan(k), "paper", params, **options) for k in range(seq.n_scans)
    ]


def _identities(lg, seq, feats) -> dict[int, int]:
    """Landmark id (as tracked before any merge) -> the simulated tree most of its
    measurements' beams hit."""
    tracks = lg.meas_track if lg.meas_track_unmerged is None else lg.meas_track_unmerged
    votes: dict[int, list] = {}
    n_beams = seq.scan_labels.shape[1]
    for r in np.flatnonzero(tracks >= 0):
        k, f = int(lg.meas_scan[r]), int(lg.meas_feature[r])
        a, b = feats[k].circle_beams[f]
        labels = seq.scan_labels[k, np.arange(a, b + 1) % n_beams]
        labels = labels[labels >= 0]
        if labels.size:
            votes.setdefault(int(tracks[r]), []).append(int(np.bincount(labels).argmax()))
    return {t: int(np.bincount(v).argmax()) for t, v in votes.items()}


def _figures(lg, seq, feats, k_return: int) -> dict:
    """One filter run's figures (module doc)."""
    truth = interpolate_poses(seq.scan_t, seq.truth_t, seq.truth_pose)
    err = np.hypot(*(lg.pose[:, :2] - truth[:, :2]).T)
    e = (lg.pose - truth)[k_return:]  # after the return (the start is exact: no NEES)
    e[:, 2] = se2.wrap_angle(e[:, 2])
    nees = np.einsum("ni,nij,nj->n", e, np.linalg.inv(lg.pose_cov[k_return:]), e)
    lo, hi = chi2.ppf(0.025, 3), chi2.ppf(0.975, 3)
    ident = _identities(lg, seq, feats)
    right = wrong = false = 0
    for ev in lg.closures or []:
        if ev["outcome"] != "accepted":
            continue
        ok = [ident.get(a) is not None and ident.get(a) == ident.get(b) for a, b in ev["merged"]]
        right, wrong, false = right + sum(ok), wrong + len(ok) - sum(ok), false + (not all(ok))
    final = [ident[int(i)] for i in lg.landmark_id if int(i) in ident]
    return {
        "landmarks": int(lg.landmark_id.size),
        "duplicates": len(final) - len(set(final)),
        "closures": sum(ev["outcome"] == "accepted" for ev in lg.closures or []),
        "false_closures": false,
        "pairs_right": right,
        "pairs_wrong": wrong,
        "final_error_m": float(err[-1]),
        "nees_inside": float(np.mean((nees >= lo) & (nees <= hi))),
        "error": err,
    }


def loop_trial(job: tuple, seed=None) -> dict:
    """One run (`job` = (kind, index)): the drive of seed `index` and each filter of
    `JACOBIANS` without and with loop closure; deterministic. Keys "<figure>_<jacobians>_<off
    or on>" and "drift_at_return_m_<jacobians>"."""
    kind, index = job
    seq, feats = drive_features(index, kind)
    x_truth = interpolate_poses(seq.scan_t, seq.truth_t, seq.truth_pose)[:, 0]
    half = seq.n_scans // 2  # the return is in the second half of the lap
    k_return = half + int(np.argmax(x_truth[half:] > HOME_X_M))
    row = {"kind": kind, "run": index}
    for jac, fej in JACOBIANS.items():
        for closure in (False, True):
            lg = run_slam(seq, loop_config(closure, first_estimates=fej), features=feats)
            f = _figures(lg, seq, feats, k_return)
            if not closure:
                row[f"drift_at_return_m_{jac}"] = float(f["error"][k_return])
            tag = f"{jac}_{'on' if closure else 'off'}"
            row |= {f"{k}_{tag}": v for k, v in f.items() if k != "error"}
    return row


FIGURE_DRIVE = 5  # the park drive of the figure: one accepted closure (its test is the same)


def closure_products(seed: int) -> dict[str, bytes]:
    """loop_closure_map.png: park drive `seed` filtered without and with loop closure; and
    loop_closure.rrd: the run with closure, recorded as it goes (each match tried past the
    count and each duplicate sweep marked on the timeline, `events/closures`)."""
    from experiments.render.viz import MemoryRecorder

    seq, feats = drive_features(seed, "park")
    truth = interpolate_poses(seq.scan_t, seq.truth_t, seq.truth_pose)
    off = run_slam(seq, loop_config(False), features=feats)
    with MemoryRecorder("slam", series=slam_panels(True)) as rec:
        rec.log_truth_trees(seq.truth_landmarks)
        on = run_slam(seq, loop_config(True), features=feats, visualiser=rec)
        rec.log_series(on.scan_t, slam_series(on, seq.truth_t, seq.truth_pose))
    runs = {}
    for closure, lg in ((False, off), (True, on)):
        at = [e["scan"] for e in lg.closures or [] if e["outcome"] == "accepted"]
        label = f"closure {'on' if closure else 'off'}: final error " + (
            f"{np.hypot(*(lg.pose[-1, :2] - truth[-1, :2])):.2f} m"
        )
        runs[label] = {"path": lg.pose[:, :2], "landmarks": lg.landmark_xy,
                       "closures": lg.pose[at, :2]}  # fmt: skip
    title = f"Simulated park, drive {seed}: one lap, out through open ground and back"
    png = products.png(
        loop_closure_figures.plot_loop_closure,
        seq.truth_landmarks[:, :2],
        truth[:, :2],
        runs,
        title,
    )
    return {"loop_closure_map.png": png, "loop_closure.rrd": rec.data}


def _summary(rows: list[dict]) -> list[dict]:
    out = []
    for kind in RUNS:
        rs = [r for r in rows if r["kind"] == kind]
        if rs:
            out += [_summary_row(rs, kind, jac, c) for jac in JACOBIANS for c in ("off", "on")]
    return out


def _summary_row(rs: list[dict], kind: str, jac: str, closure: str) -> dict:
    """The table's row of one scene, filter and closure setting."""
    drift = np.array([r[f"drift_at_return_m_{jac}"] for r in rs])
    band = (drift >= 2.0) & (drift <= 5.0)

    def col(name):
        return np.array([r[f"{name}_{jac}_{closure}"] for r in rs], dtype=float)

    return {
        "scene": kind,
        "jacobians": jac,
        "closure": closure,
        "runs": len(rs),
        "drift_at_return_median_m": float(np.median(drift)),
        "returns_2_5_m": int(band.sum()),
        "with_closure_2_5_m": int(np.sum(band & (col("closures") > 0))),
        "closed_2_5_m": int(np.sum(band & (col("duplicates") == 0))),
        "closures": int(col("closures").sum()),
        "false_closures": int(col("false_closures").sum()),
        "pairs_wrong": int(col("pairs_wrong").sum()),
        "landmarks_mean": float(col("landmarks").mean()),
        "duplicates_mean": float(col("duplicates").mean()),
        "final_error_median_m": float(np.median(col("final_error_m"))),
        "nees_inside_after_return": float(col("nees_inside").mean()),
    }


LABELS = {
    "runs": "runs",
    "drift_at_return_median_m": "drift at return, median (m)",
    "returns_2_5_m": "returns drifted 2-5 m",
    "with_closure_2_5_m": "of them with a closure",
    "closed_2_5_m": "of them closed",
    "closures": "closures accepted",
    "false_closures": "false closures",
    "pairs_wrong": "pairs of different trees",
    "landmarks_mean": "landmarks, mean",
    "duplicates_mean": "trees mapped twice, mean",
    "final_error_median_m": "final error, median (m)",
    "nees_inside_after_return": "pose NEES inside 95% bounds after return",
}
PARTS = (
    ("Returns and closures", tuple(list(LABELS)[:8])),
    ("Map and path", tuple(list(LABELS)[8:])),
)
TABLE = TableSpec(
    "loop_closure",
    _summary,
    index=("scene", "jacobians", "closure"),
    values=tuple(LABELS),
    parts=PARTS,
    labels=LABELS,
    title="Simulated loops: loop closure off and on",
    notes=(
        "experiments/paper/loop_closure.py. Each run: one lap of a stand of trees (park: 45 "
        "at random; orchard: 60 on a 4 m x 6 m grid), out through open ground and back, with "
        f"the Cycab's odometry noise x {NOISE_SCALE}, filtered without and with [closure], "
        "with standard and with first-estimates Jacobians ([filter] "
        "first_estimates_jacobians). "
        "Of them with a closure: returns that drifted 2-5 m with an accepted closure; closed: "
        "those that end with no tree mapped twice. False closures: accepted closures with a "
        "pair of different trees (a landmark is the tree most of its measurements hit)."
    ),
)


@experiment(
    "loop-closure",
    order=120,
    page="loop-closure.md",
    help="simulated loops in a park and an orchard, loop closure off and on (only when named)",
    default=False,
)
def run(ctx) -> None:
    """The registered experiment `loop-closure` (only when named)."""
    jobs = [(kind, i) for kind, n in RUNS.items() for i in range(QUICK_RUNS if ctx.quick else n)]
    batch = ctx.submit(loop_trial, jobs, desc="loop-closure runs", chunksize=1)

    def finish(rows: list) -> None:
        ctx.config["loop-closure"] = {"runs": len(rows), "noise_scale": NOISE_SCALE}
        products.tables(ctx, [TABLE], rows)
        products.write(ctx, closure_products(FIGURE_DRIVE))

    ctx.later(batch, finish)
