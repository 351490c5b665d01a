"""`trunkslam slam`: read a sequence file, run EKF-SLAM, write the trajectory, map and summary."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from experiments.errors import DataError
from experiments.eval.gospa import GOSPA_SETTINGS, gospa, ospa
from experiments.eval.gps import RFS_TOLERANCE_S, score_sequence
from experiments.eval.missing import null_scores
from experiments.eval.poses import nees, pose_errors
from experiments.eval.series import slam_panels, slam_series
from experiments.eval.vouched import vouched_for_sequence
from experiments.io.config_file import config_toml
from experiments.io.features_json import load_features_json
from experiments.io.outputs import check_output_folder, check_outputs, lock_folder, write_manifest
from experiments.io.reference_map import read_reference_map
from experiments.io.results import map_csv, trajectory_csv, trajectory_tum
from experiments.io.run_log import RUN_LOG_NAME, write_run_log
from experiments.io.sequence_file import load_sequence
from experiments.io.writers import atomic_folder, dumps_json, json_types, write_atomic
from experiments.pipeline.built_in import built_in_note
from experiments.render.compiling import compile_seconds, watch_compiles
from experiments.render.recording import open_recording
from experiments.render.rerun_sink import recording_file
from slam import Sequence, SlamConfig, SlamLog, interpolate_poses, run_slam, se2
from slam.closure import closure_counts

__all__ = ["landmark_radii", "reference_map_scores", "run_slam_file", "summarise"]


def run_slam_file(
    input_path: Path | str,
    config: SlamConfig | None = None,
    out_dir: Path | str = Path("slam_out"),
    *,
    rerun_path: Path | str | None = None,
    progress=None,
    ellipse_scale: float = 10.0,
    inputs: tuple = (),
    reference_map: Path | str | None = None,
) -> dict:
    """Run EKF-SLAM over the sequence file `input_path` as `config` says (default
    `SlamConfig()`; `features.file`, when set, is a features JSON from `trunkslam extract` whose
    circles are used instead of extracting) and write the results into out_dir.

    Writes
    trajectory.tum   the rear-axle centre at the scan times, `t x y z qx qy qz qw` (z = 0,
                     rotation about z by theta), readable by evo
    trajectory_gps_antenna.tum  the same path at the GPS antenna (sequences with GPS), to compare
                     with `trunkslam export-reference`'s gps.tum
    trajectory.csv   t_s, the rear-axle centre's pose in the world frame and the upper triangle
                     of its covariance, units in the column names (`io.results.TRAJECTORY_COLUMNS`)
    map.csv          id, centre (world), radius, covariance (xx, xy, yy), scan it joined the
                     map, scans seen in (`io.results.MAP_COLUMNS`)
    config.toml      the whole configuration of the run: `--config` with it reproduces the run
    run_log.npz      what the GTSAM smoother needs (`trunkslam smooth`; experiments.io.run_log)
    summary.json     input, methods, start, counts, timings (mean, median, p95, max per phase),
                     errors against GPS (`experiments.eval.gps`) when the sequence has GPS, and
                     against the truth (Table-3 errors, mean NEES) when it has truth, and the
                     map's GOSPA against `reference_map` when given (`reference_map_scores`)
    manifest.json    every file of the set (`experiments.io.outputs.write_manifest`)
    Returns the summary. rerun_path: also write a recording (`experiments.render.viz`, kind
    "slam"; simulated truth trees and path when the sequence has them), or stream it to a live
    viewer (an `experiments.render.rerun_sink.Viewer`), its covariance
    ellipses drawn `ellipse_scale` times their 95% size. reference_map: a CSV of x,y (m, the
    run's world frame; `experiments.io.reference_map`), read and checked before the run.

    The files are written as one set (`experiments.io.writers.atomic_folder`): into a temporary
    folder beside out_dir, summary.json and manifest.json last, then swapped for out_dir as a
    whole; an interruption or a write error leaves the previous out_dir as it was. out_dir must
    be absent, empty or an earlier `trunkslam slam` output every file of which its manifest
    lists, and must not hold the inputs (the sequence, the features file, `inputs`: the
    --config file); it is held (`lock_folder`) from the checks to the swap. The recording
    (rerun_path) is written to a temporary name and renamed; inside out_dir it becomes part of
    the set.
    """
    cfg = config or SlamConfig()
    features_file = cfg.features.file
    out = Path(out_dir)
    check_outputs(
        "slam",
        inputs=[input_path, features_file, reference_map, *inputs],
        files={"--rerun": recording_file(rerun_path)},
        folders={"--out": out},
    )
    rerun_in_out = _recording_place(recording_file(rerun_path), out)
    reference = (
        None if reference_map is None else (reference_map, read_reference_map(reference_map))
    )
    with lock_folder(out, "--out"):
        check_output_folder(out, "--out", "slam")  # again: now no other command changes it
        rerun = (rerun_path, rerun_in_out)
        view = (progress, ellipse_scale)
        return _run_into(out, (input_path, features_file, reference), cfg, rerun, view)


def _run_into(out: Path, inputs, cfg: SlamConfig, rerun, view) -> dict:
    """The run and its files (`run_slam_file`'s body, out held); inputs: (sequence, features
    file, (reference map file, its points) or None), rerun: (path, its place inside out or
    None), view: (progress, ellipse scale)."""
    input_path, features_file, reference = inputs
    rerun_path, rerun_in_out = rerun
    seq = load_sequence(input_path)
    note = built_in_note(seq, cfg)  # logged before the run: which settings are neutral
    given = None
    if features_file is not None:
        given = load_features_json(features_file, seq.n_scans, seq.n_beams)
    with atomic_folder(out) as stage:
        rec_path = rerun_path if rerun_in_out is None else stage / rerun_in_out
        watch_compiles()  # the run's time leaves numba's first compile out, reported apart
        c0, t0 = compile_seconds(), time.perf_counter()
        lg = _run_recorded(seq, cfg, given, rec_path, view)
        compiling = compile_seconds() - c0
        seconds = time.perf_counter() - t0 - compiling
        _write_run(stage, seq, cfg, lg, f"trunkslam slam {input_path}")
        summary = summarise(lg, seq, seconds)
        summary = {"input": str(input_path), "features_file": _str(features_file), **summary}
        if note is not None:
            summary["built_in_settings"] = note
        if reference is not None:
            summary["reference_map"] = reference_map_scores(lg.landmark_xy, *reference)
        summary["compile_s"] = compiling  # 0 once the kernels are in numba's cache
        write_atomic(stage / SUMMARY, dumps_json(summary))
        write_manifest(stage, "slam")  # last: the set is complete
    return summary


def _recording_place(rerun_path, out: Path) -> Path | None:
    """Where a --rerun path lies inside the --out folder (None: outside it)."""
    if rerun_path is None:
        return None
    rerun_path = Path(rerun_path)
    if rerun_path.resolve().is_relative_to(out.resolve()):
        inside = rerun_path.resolve().relative_to(out.resolve())
        if inside == Path("."):
            raise DataError(f"--rerun {rerun_path}: is the --out folder")
        return inside
    return None


def _run_recorded(seq: Sequence, cfg: SlamConfig, given, rec_path, view) -> SlamLog:
    """The run, recorded to `rec_path` when given; view = (progress callback, ellipse scale)."""
    progress, ellipse_scale = view
    has_truth = seq.truth_t is not None
    with open_recording(
        rec_path, "slam", ellipse_scale=ellipse_scale, series=slam_panels(has_truth)
    ) as rec:
        if seq.truth_landmarks is not None:
            rec.log_truth_trees(seq.truth_landmarks)
        lg = run_slam(seq, cfg, features=given, visualiser=rec, progress=progress)
        rec.log_series(lg.scan_t, slam_series(lg, seq.truth_t, seq.truth_pose))
    return lg


def _write_run(stage: Path, seq: Sequence, cfg: SlamConfig, lg: SlamLog, command: str) -> None:
    """The run's files but the summary: trajectories, map, configuration, run log."""
    write_atomic(stage / "trajectory.tum", trajectory_tum(lg.scan_t, lg.pose))
    if seq.gps_t is not None:
        xy = np.array([se2.compose(p, lg.antenna_pose) for p in lg.pose])
        write_atomic(stage / "trajectory_gps_antenna.tum", trajectory_tum(lg.scan_t, xy))
    write_atomic(stage / "trajectory.csv", trajectory_csv(lg.scan_t, lg.pose, lg.pose_cov))
    write_atomic(
        stage / "map.csv",
        map_csv(
            lg.landmark_id,
            lg.landmark_xy,
            lg.landmark_cov,
            first_scan=lg.landmark_first_scan,
            n_obs=lg.landmark_n_obs,
            radius_m=landmark_radii(lg),
        ),
    )
    write_atomic(stage / "config.toml", config_toml(cfg, command))
    write_run_log(stage / RUN_LOG_NAME, lg)


SUMMARY = "summary.json"


def landmark_radii(lg: SlamLog) -> np.ndarray:
    """(n,) median radius, m, of the circles that updated each landmark of the final map (NaN
    when none has a radius)."""
    out = np.full(lg.landmark_id.size, np.nan)
    for j, i in enumerate(lg.landmark_id):
        r = lg.meas_radius_m[(lg.meas_status == i) & np.isfinite(lg.meas_radius_m)]
        if r.size:
            out[j] = float(np.median(r))
    return out


def _str(p) -> str | None:
    return None if p is None else str(p)


def _joint_dropped(lg: SlamLog) -> dict:
    """The summary's joint_check part: the pairings `[association] joint_check` dropped and
    the scans it dropped any in."""
    scans = {row[0] for row in lg.joint_dropped}
    return {"dropped": len(lg.joint_dropped), "scans": len(scans)}


def summarise(lg: SlamLog, seq: Sequence, seconds: float) -> dict:
    """Counts, timings per phase, the configuration, errors against GPS (when the sequence has
    GPS) and against the truth (scans the truth covers, the first left out since the run may
    start there; but for `rmse_m`, evo's figure, which counts it)."""
    timing = {}
    for k, v in lg.timing_s.items():
        timing[k] = {
            "mean_ms": 1e3 * float(np.mean(v)),
            "median_ms": 1e3 * float(np.median(v)),
            "p95_ms": 1e3 * float(np.percentile(v, 95)),
            "max_ms": 1e3 * float(np.max(v)),
            "total_s": float(np.sum(v)),
        }
    summary = {
        "features": lg.features_method,
        "association": lg.association_method,
        "n_scans": lg.n_scans,
        "start": lg.start,
        "start_pose": [float(v) for v in lg.pose[0]],
        "landmarks": int(lg.landmark_xy.shape[0]),
        "circles_per_scan": float(lg.n_features.mean()),
        "associated_per_scan": float(lg.n_associated.mean()),
        "scans_skipped": int(lg.scan_skipped.sum()),  # predicted only (min_travel_m)
        "seconds": seconds,
        "timing": timing,
        "config": json_types(lg.config),
        **({"window": lg.window_stats} if lg.window_stats else {}),
        **({"closures": _closures(lg)} if lg.closures is not None else {}),
        **({"joint_check": _joint_dropped(lg)} if lg.joint_dropped is not None else {}),
    }
    if seq.gps_t is not None:
        vouched = vouched_for_sequence(seq, SlamConfig.from_dict(lg.config))
        score = score_sequence(seq, lg.scan_t, lg.pose, lg.antenna_pose, vouched)
        summary["gps"] = {**score.to_dict(), "antenna_pose": lg.antenna_pose.tolist()}
    inside = (
        np.zeros(seq.n_scans, bool)
        if seq.truth_t is None
        else (lg.scan_t >= seq.truth_t[0]) & (lg.scan_t <= seq.truth_t[-1])
    )
    covered = inside.copy()  # evo_ape's pairing against truth.tum: the first scan included
    inside[0] = False  # the run may start at the truth
    if inside.any():  # score only the scans the truth covers, at the poses' own times
        truth = interpolate_poses(lg.scan_t, seq.truth_t, seq.truth_pose)
        e_all = pose_errors(lg.pose, truth)
        e = e_all[inside]
        covs = lg.pose_cov[inside]
        ok = np.linalg.det(covs) > 0
        n = nees(e[ok], covs[ok])
        summary["truth"] = {
            "mean_abs_error": dict(
                zip(("dx_m", "dy_m", "dtheta_rad"), np.mean(np.abs(e), 0).tolist())
            ),
            "nees_mean": float(np.mean(n)) if n.size else None,
            "scans_scored": int(inside.sum()),
            # position RMSE over every scan the truth covers, the first too: evo_ape's figure
            # against `trunkslam export-reference`'s truth.tum
            "rmse_m": float(np.sqrt(np.mean(np.sum(e_all[covered, :2] ** 2, axis=1)))),
        }
    return null_scores(summary, reasons=missing_reasons(seq, summary))


def reference_map_scores(landmark_xy: np.ndarray, path, trees: np.ndarray) -> dict:
    """The summary's reference_map part: the file, its landmarks, and the map's GOSPA against
    them at c = 1 m and c = 20 m (p = 2, alpha = 2; `experiments.eval.gospa`), each with its
    localisation, missed and false parts (m^2) and counts, and OSPA (p = 2) at the same c."""
    out: dict = {"file": str(path), "landmarks": int(trees.shape[0])}
    for c, p, alpha in GOSPA_SETTINGS:
        out[f"gospa_{c:g}m"] = gospa(landmark_xy, trees, p=p, c=c, alpha=alpha).to_dict()
        out[f"ospa_{c:g}m"] = ospa(landmark_xy, trees, p=p, c=c)
    return out


def _closures(lg) -> dict:
    """The summary's loop closure part: matches tried by outcome, landmarks merged by them and
    by the duplicate sweep, and the accepted closures (scan, time, pairs, NIS, transform,
    whether re-registered)."""
    events = lg.closures
    out = closure_counts(events, lg.closure_duplicates)
    keys = ("scan", "t_s", "best", "second", "nis", "nis_bound", "rotation_deg", "shift_m",
            "re_registered")  # fmt: skip
    out["accepted_closures"] = [
        {k: e[k] for k in keys} for e in events if e["outcome"] == "accepted"
    ]
    return out


def missing_reasons(seq: Sequence, summary: dict) -> dict[str, str]:
    """Why a score of `summary` could not be computed, by section (`null_scores`)."""
    out = {"truth": "too few scans inside the truth's time span to compute it"}
    gps = summary.get("gps") or {}
    span = f"{seq.scan_t[0]:.3f}-{seq.scan_t[-1]:.3f} s"
    if not gps.get("matched"):
        out["gps"] = f"no GPS fix within the run's time span ({span}); all are outside it"
        return out
    out["gps"] = f"too few GPS fixes within the run ({gps['matched']}) to compute it"
    return out | gps_reasons(gps)


def gps_reasons(gps: dict) -> dict[str, str]:
    """Why each GPS figure a run with fixes inside it can still lack is missing: its rule and
    the count of the fixes it counts (`experiments.eval.gps`), by dotted key."""
    n, clean = gps["matched"], gps["matched"] - gps.get("jumps", 0)
    out = {}
    for k in ("clean_rmse", "clean_median", "clean_p95"):
        out[f"gps.{k}"] = f"no fix that is not a jump among the {n} within the run"
    for k in ("rotation_deg", "all_rmse_aligned", "clean_rmse_aligned", "clean_median_aligned",
              "clean_p95_aligned"):  # fmt: skip
        out[f"gps.{k}"] = (
            f"the alignment needs at least 3 fixes within the run that are not jumps; {clean} are"
        )
    for k in ("vouched_rmse", "vouched_median", "vouched_p95"):
        out[f"gps.{k}"] = (
            f"none of the {n} fixes within the run is vouched for by the odometry "
            "(experiments.eval.vouched)"
        )
    ms = 1e3 * RFS_TOLERANCE_S
    out["gps.rfs_rmse"] = f"none of the {n} fixes within the run is within {ms:g} ms of a scan"
    return out
