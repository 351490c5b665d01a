"""Experiment `victoria-park`: EKF-SLAM on the real run, scored against GPS, beside published runs.

Rows (one per input, features and association), all with the preset
experiments/presets/victoria_park_ute.toml (derived from scans 1-2000 by
`trunkslam reproduce victoria-park-calibration`, never from a GPS error):
- the full run (7249 scans, 1548 s) with the published detections, associated by IHGR, JCBB, NN;
- scans 1-2000 (the part with raw laser data) with the published detections, and with circles
  from our extractors on the raw scans: `bailey` (the same detector, reproduced), `paper`,
  `geometric`.
Columns: the GPS figures of `experiments.eval.gps` (antenna point, every matched fix, raw and
after a rigid alignment; jumps flagged and counted), the same RMSE over scans 2001-7249 alone
(the part the calibration never saw), landmarks, reference trees matched (the 2002 SLAM
school's map of 145 trees over scans 1-2000, aligned by the two paths: the share of its trees
with a landmark within 1 m), NIS inside its 95% bounds, circles per scan, seconds, ms per scan.

Writes victoria_park.md/.csv, vp_map.png (map and path over the GPS track), vp_closures.png
(the run with loop closure: where each match was tried and how it ended), vp_timeseries.png
(error against time with the GPS gaps shaded, NIS and map size against time) and
victoria_park.rrd (the full IHGR run, timelines `scan` and `time`). Skipped, with a note in the
manifest, when the data is absent. --quick: the first 1500 scans of the full run, 400 of the raw.
The runs are trials on the executor; the first (the full IHGR run) is recorded as it goes and
draws the figures, so no run is repeated for them and nothing heavy runs in the main process,
which writes the files once every experiment has started (`RunContext.later`).
"""

from __future__ import annotations

import dataclasses
import functools
import logging
import math
import time

import numpy as np
from scipy.stats import chi2

from experiments.errors import MissingDataError
from experiments.eval.gospa import GOSPA_LABELS, GOSPA_SETTINGS, gospa_columns
from experiments.eval.gps import score_sequence
from experiments.eval.map_quality import (
    false_detection_rate,
    map_precision,
    map_recall,
    one_tree_pairs,
    reference_in_our_frame,
    seen_trees,
)
from experiments.eval.series import slam_panels, slam_series
from experiments.eval.vouched import vouched_for_sequence
from experiments.io.config_file import config_toml, load_slam_config
from experiments.io.victoria_park import (
    VP_N_RAW_SCANS,
    VP_N_SCANS,
    load_ss2002_reference,
    load_victoria_park,
)
from experiments.io.writers import json_types, write_atomic
from experiments.paper import products
from experiments.paper.products import TableSpec
from experiments.paper.registry import experiment
from slam import SlamConfig, SlamLog, run_slam, se2
from slam.closure import closure_counts
from slam.log import OUT_OF_RANGE, SKIPPED

__all__ = [
    "GPS_GAP_S",
    "HALVES",
    "PRESET",
    "PARTS",
    "PUBLISHED",
    "PUBLISHED_TABLE",
    "TABLE",
    "head",
    "nis_inside",
    "reference_match",
    "run",
    "table_records",
    "vp_trial",
]

log = logging.getLogger(__name__)

PRESET = "victoria_park_ute"
METHODS = ("ihgr", "jcbb", "nn")
# The GPS reports every 0.2 s (median) with dropouts; the figures shade a time of more than this
# without a fix, and their lines stop there (the GPS reported no position in it).
GPS_GAP_S = 2.0
# Published figures for this dataset, each with where it comes from (a repository's README at
# the commit read; their set-ups differ from ours and from each other). Printed once, in their
# own table (`PUBLISHED_TABLE`). Left out, for want of a source: "PHD-SLAM 2.5-4.4 m" and
# "EKF + JCBB, 1686 landmarks, NIS inside 0.66" (the issue list they came from names none).
PUBLISHED = (
    {
        "run": "EKF, Q and R tuned by Bayesian optimisation on the GPS error (course project)",
        "rmse_m": 1.394,
        "landmarks": 182,
        "protocol": "its own ATE RMSE against the GPS, which its Bayesian optimisation of Q "
        "and R minimised (with a landmark-count term)",
        "reference": "github.com/0123gabriel/SLAM-VictoriaPark README.md at a49a4f8 (2025-06-21; "
        "unchanged at 182d1d5), static landmarks; not Zamora et al., whose repository "
        "publishes no RMSE",
    },
    {
        "run": "GM-PHD-PMAU-SLAM",
        "rmse_rfs_m": 2.55,
        "protocol": "RFS: 100 clutter draws, fixed start, 25 ms rule (victoria-park-rfs)",
        "reference": "github.com/baizhiyuan/GM-PHD-PMAU-SLAM README.md at e5ba034 (2024-10-30; "
        "the figure since 6cbc450, 2024-10-23), one particle",
    },
    {
        "run": "LGM-PHD-PMAU-SLAM (labelled, relocalises)",
        "rmse_rfs_m": 2.46,
        "protocol": "RFS: 100 clutter draws, fixed start, 25 ms rule (victoria-park-rfs)",
        "reference": "github.com/baizhiyuan/GM-PHD-PMAU-SLAM README.md at e5ba034 (2024-10-30; "
        "the figure since 6cbc450, 2024-10-23), one particle",
    },
    {
        "run": "PHD-SLAM 3.0",
        "rmse_rfs_low_m": 3.36,
        "rmse_rfs_high_m": 3.57,
        "protocol": "RFS: 100 clutter draws, fixed start, 25 ms rule (victoria-park-rfs)",
        "reference": "github.com/okaltiok/PHD-SLAM-3.0 README.md at 35a64de (2024-12-07): 3.57, "
        "3.38, 3.36 m with 1, 5, 10 particles; the README said 4.37, 2.84, 2.88 m with 1, 10, "
        "100 particles at 16f625a (2022-09-05), 3.91 m (1) from ca43875 (2022-10-05), 3.57 m "
        "(1) from 64a6c61 (2023-03-08)",
    },
)
PUBLISHED_COLUMNS = {
    "rmse_m": "RMSE, its own protocol (m)",
    "rmse_rfs_m": "RMSE, RFS protocol (m)",
    "rmse_rfs_low_m": "RMSE, RFS protocol, from (m)",
    "rmse_rfs_high_m": "RMSE, RFS protocol, to (m)",
    "landmarks": "landmarks",
}


def nis_inside(lg: SlamLog) -> np.ndarray:
    """(scans with an update,) bool: the batch NIS inside its two-sided 95% chi-square bounds."""
    ok = lg.scan_nis_dof > 0
    dof = lg.scan_nis_dof[ok]
    nis = lg.scan_nis[ok]
    return (nis >= chi2.ppf(0.025, dof)) & (nis <= chi2.ppf(0.975, dof))


def reference_match(lg: SlamLog, laser_pose, ground: np.ndarray, trees: np.ndarray) -> dict:
    """The run's map against the 2002 reference of scans 1-2000 (`experiments.eval.map_quality`,
    the reference mapped onto our frame by the rigid fit of its laser path to ours):
    reference_trees_1m (recall: reference trees with a landmark within 1 m), precision_1m
    (landmarks that joined in scans 1-2000 with a reference tree within 1 m),
    false_detection_rate (circles no landmark of the final map explains), and the pairs of
    landmarks within 1.5 m, with those of them the reference or the laser says are one tree
    (`one_tree_pairs`). Each half of scans 1-2000 (`HALVES`) apart: precision, false
    detections, and recall over the reference trees a circle the filter considered came within
    1 m of in that half (`seen_trees`; reference_trees_seen_1m: the same over the run's span).
    GOSPA (`experiments.eval.gospa.gospa_columns`: c = 1 m and 20 m, p = 2, alpha = 2, with
    the localisation, missed and false parts) of the landmarks that joined in scans 1-2000
    against all the reference trees."""
    n = min(ground.shape[0], lg.n_scans)
    ours = np.array([se2.compose(p, laser_pose)[:2] for p in lg.pose[:n]])
    tw = reference_in_our_frame(ours, ground, trees)
    out = {
        "reference_trees_1m": map_recall(lg.landmark_xy, tw),
        "precision_1m": map_precision(lg.landmark_xy, lg.landmark_first_scan, tw, n),
        "false_detection_rate": false_detection_rate(lg.meas_status, lg.meas_track, lg.landmark_id),
    }
    out["close_pairs"], out["one_tree_pairs"] = one_tree_pairs(
        lg.landmark_xy, lg.landmark_id, (lg.obs_scan, lg.obs_landmark), tw
    )
    # the circles the filter considered in the reference's span, placed by the run's poses
    used = (lg.meas_status != OUT_OF_RANGE) & (lg.meas_status != SKIPPED) & (lg.meas_scan < n)
    scan = lg.meas_scan[used]
    circles = se2.observed_points(lg.pose[scan], lg.meas_z[used], laser_pose)

    def seen_recall(inside: np.ndarray) -> float:
        seen = seen_trees(circles[inside], tw)
        return map_recall(lg.landmark_xy, tw[seen]) if seen.any() else math.nan

    out["reference_trees_seen_1m"] = seen_recall(np.ones(scan.size, bool))
    for a, b in HALVES:  # the generalisation check: each half of the reference's span alone
        out[f"reference_trees_seen_1m_{a + 1}_{b}"] = seen_recall((scan >= a) & (scan < b))
        out[f"precision_{a + 1}_{b}"] = map_precision(
            lg.landmark_xy, lg.landmark_first_scan, tw, min(b, n), start=a
        )
        m = (lg.meas_scan >= a) & (lg.meas_scan < b)
        out[f"false_detection_rate_{a + 1}_{b}"] = false_detection_rate(
            lg.meas_status[m], lg.meas_track[m], lg.landmark_id
        )
    # GOSPA of the landmarks judged for precision (joined in scans 1-2000) against all 145 trees
    out.update(gospa_columns(lg.landmark_xy[lg.landmark_first_scan < n], tw))
    return out


# the halves of scans 1-2000 reported apart: a setting derived on the first half alone is
# judged on the second, which it never saw
HALVES = ((0, 1000), (1000, 2000))


def _published_matched(seq, feats) -> float:
    """Share of the published detections with one of our circles within 0.5 m (laser frame)."""
    hit = total = 0
    for k, f in enumerate(feats):
        z, _, _ = seq.detections(k)
        pub = np.column_stack([z[:, 0] * np.cos(z[:, 1]), z[:, 0] * np.sin(z[:, 1])])
        total += pub.shape[0]
        if pub.shape[0] and f.n_circles:
            c = f.circle_params[:, :2]
            d = np.hypot(pub[:, None, 0] - c[None, :, 0], pub[:, None, 1] - c[None, :, 1])
            hit += int(np.sum(d.min(axis=1) <= 0.5))
    return hit / max(total, 1)


class _Timed:
    """A visualiser that forwards every call to `inner` and counts the seconds spent there: a
    recorded run's time without its recording."""

    def __init__(self, inner) -> None:
        self.inner = inner
        self.seconds = 0.0

    def __getattr__(self, name: str):
        method = getattr(self.inner, name)

        def timed(*args, **kwargs):
            t0 = time.perf_counter()
            try:
                return method(*args, **kwargs)
            finally:
                self.seconds += time.perf_counter() - t0

        return timed


def run_config(features: str, association: str) -> SlamConfig:
    """The configuration of a run of the table: the preset with its features' and association's
    methods replaced (the preset's extractor parameters hold for every extractor);
    association "METHOD+closure" also turns loop closure on (`slam.closure`)."""
    method, _, extra = association.partition("+")
    cfg = load_slam_config(PRESET)
    cfg = cfg.with_(**{"features.method": features, "association.method": method})
    return cfg.with_(**{"closure.enabled": True}) if extra == "closure" else cfg


def _one(label, seq, cfg, ref, given=None, visualiser=None):
    """(row, log, GPS score) of the run of `cfg` over `seq`; `given`: its features, extracted
    by the caller as `cfg` says (they are then not extracted twice)."""
    vis = _Timed(visualiser) if visualiser is not None else None
    t0 = time.perf_counter()
    lg = run_slam(seq, cfg, features=given, visualiser=vis)
    seconds = time.perf_counter() - t0 - (vis.seconds if vis is not None else 0.0)
    vouched = _vouched(seq, cfg)
    sc = score_sequence(seq, lg.scan_t, lg.pose, lg.antenna_pose, vouched)
    late = sc.t_s > seq.scan_t[min(VP_N_RAW_SCANS, seq.n_scans) - 1]
    rmse_late = float(np.sqrt(np.mean(sc.errors[late] ** 2))) if late.any() else math.nan
    row = {
        "run": label,
        "scans": lg.n_scans,
        "association": lg.association_method,
        "rmse_m": sc.all_rmse,
        "median_m": sc.all_median,
        "p95_m": sc.all_p95,
        "rmse_clean_m": sc.clean_rmse,
        "rmse_aligned_m": sc.all_rmse_aligned,
        "median_aligned_m": sc.clean_median_aligned,
        "p95_aligned_m": sc.clean_p95_aligned,
        "rotation_deg": sc.rotation_deg,
        "rmse_2001_7249_m": rmse_late,
        "fixes_vouched": sc.vouched,
        "rmse_vouched_m": sc.vouched_rmse,
        "median_vouched_m": sc.vouched_median,
        "p95_vouched_m": sc.vouched_p95,
        "rmse_rfs_m": sc.rfs_rmse,
        "fixes": sc.matched,
        "jumps": sc.jumps,
        "landmarks": int(lg.landmark_xy.shape[0]),
        **reference_match(lg, lg.laser_pose, *ref),
        "nis_inside": float(np.mean(nis_inside(lg))),
        "circles_per_scan": float(lg.n_features.mean()),
        "seconds": seconds,
        "ms_per_scan": 1e3 * float(np.mean(lg.timing_s["total"])),
        **_closure_figures(lg),
    }
    if given is not None:
        row["published_matched"] = _published_matched(seq, given)
    return row, lg, sc


def _closure_figures(lg) -> dict:
    """Loop closure's figures of a run (`slam.closure`; NaN when it was off): constellation
    matches tried, refused as not jointly compatible, accepted, landmarks merged by them, and
    landmarks the duplicate sweep marginalised out."""
    names = {  # column: key of `slam.closure.closure_counts`
        "closure_matches": "tried",
        "closure_refused_jc": "not_jointly_compatible",
        "closures_accepted": "accepted",
        "landmarks_merged": "landmarks_merged",
        "duplicates_merged": "duplicates_merged",
    }
    if lg.closures is None:
        return dict.fromkeys(names, math.nan)
    counts = closure_counts(lg.closures, lg.closure_duplicates)
    return {column: counts[key] for column, key in names.items()}


def _vouched(seq, cfg) -> np.ndarray:
    """The GPS fixes of `seq` the odometry vouches for, dead-reckoned with the preset's vehicle
    (the same for every run of the table; computed once per sequence in a process)."""
    key = (id(seq), seq.n_scans)
    if key not in _VOUCHED:
        _VOUCHED[key] = vouched_for_sequence(seq, cfg)
    return _VOUCHED[key]


_VOUCHED: dict = {}


@functools.cache
def _data(quick: bool):
    """(full run, raw scans, 2002 reference), with --quick the first 1500 and 400 scans; read
    once per process (the trials of a worker share it)."""
    full = load_victoria_park(full=True)
    raw = load_victoria_park()
    if quick:
        full, raw = head(full, 1500), head(raw, 400)
    return full, raw, load_ss2002_reference()


def vp_trial(job: tuple, seed=None) -> tuple[dict, dict[str, bytes]]:
    """One row of the table (`job` = (label, "full" or "raw", features, association, quick,
    keep)): features "detections" or an extractor run on the raw scans. Deterministic (seed
    None). Returns (row, files): with `keep`, the run is recorded as it goes and files holds
    the experiment's products made from it, {file name: bytes} (victoria_park.rrd, vp_map.png,
    vp_timeseries.png); without, files is empty."""
    label, which, features, assoc, quick, keep = job
    full, raw, ref = _data(quick)
    seq = full if which == "full" else raw
    cfg = run_config(features, assoc)
    given = None
    if features != "detections":
        from features import extract_features

        params, options = cfg.features.extractor_args()
        given = [
            extract_features(seq.scan(k), features, params, **options) for k in range(seq.n_scans)
        ]
    if not keep:
        row, lg, _ = _one(label, seq, cfg, ref, given)
        return row, {} if lg.closures is None else {"vp_closures.png": _closure_map(lg, seq)}
    from experiments.render.viz import MemoryRecorder

    with MemoryRecorder("slam", decimate=20, series=slam_panels(False)) as rec:
        row, lg, sc = _one(label, seq, cfg, ref, given, visualiser=rec)
        rec.log_series(lg.scan_t, slam_series(lg))
    return row, {"victoria_park.rrd": rec.data, **_figures(label, lg, sc, seq)}


@experiment(
    "victoria-park",
    order=60,
    page="victoria-park.md",
    help="EKF-SLAM on the real run against GPS (needs the data), victoria_park.rrd",
)
def run(ctx) -> None:
    """The registered experiment `victoria-park`: its seven runs are trials (`vp_trial`); the
    first also makes the recording and the figures. The table is written after the other
    experiments have started (`RunContext.later`): the runs share the workers with theirs."""
    cfg_out = ctx.config.setdefault("victoria-park", {})
    try:
        full, raw, _ = _data(ctx.quick)
    except MissingDataError as exc:
        log.warning("Victoria Park experiment skipped: %s", exc)
        ctx.config["victoria-park"] = f"skipped: {exc}"
        return
    cfg = load_slam_config(PRESET)
    cfg_out.update(
        preset=PRESET,
        config=json_types(cfg.to_dict()),
        scans_full=full.n_scans,
        scans_raw=raw.n_scans,
    )
    jobs = [(f"full run, published detections, {a}", "full", "detections", a) for a in METHODS]
    jobs.append(
        ("full run, published detections, ihgr, loop closure", "full", "detections", "ihgr+closure")
    )
    jobs.append(("scans 1-2000, published detections, ihgr", "raw", "detections", "ihgr"))
    jobs += [
        (f"scans 1-2000, our {m} extractor on the raw scans, ihgr", "raw", m, "ihgr")
        for m in ("bailey", "paper", "geometric")
    ]
    batch = ctx.submit(
        vp_trial,
        [(*j, ctx.quick, i == 0) for i, j in enumerate(jobs)],
        desc="victoria park runs",
        chunksize=1,
    )

    def finish(got: list) -> None:
        products.tables(ctx, [TABLE, PUBLISHED_TABLE], [row for row, _ in got])
        products.write(ctx, {k: v for _, files in got for k, v in files.items()})
        for label, which, features, assoc in jobs:  # each run's configuration beside its row
            part = "full" if which == "full" else "scans_1_2000"
            name = f"victoria_park_config_{part}_{features}_{assoc.replace('+', '_')}.toml"
            data = "vp_full.npz (--full)" if which == "full" else "vp.npz"
            header = f"{label}\ntrunkslam slam {data} --config {name}"
            write_atomic(ctx.path(name), config_toml(run_config(features, assoc), header))

    ctx.later(batch, finish)


def head(seq, n: int):
    if n >= seq.n_scans:
        return seq
    keep = seq.det_scan < n
    return dataclasses.replace(
        seq,
        scan_t=seq.scan_t[:n],
        scan_ranges=None if seq.scan_ranges is None else seq.scan_ranges[:n],
        det_scan=seq.det_scan[keep],
        det_range=seq.det_range[keep],
        det_bearing=seq.det_bearing[keep],
        det_radius=seq.det_radius[keep],
    )


COLUMNS = [
    ("run", "run"),
    ("scans", "scans"),
    ("rmse_m", "RMSE (m)"),
    ("median_m", "median (m)"),
    ("p95_m", "p95 (m)"),
    ("rmse_clean_m", "RMSE without jumps (m)"),
    ("rmse_aligned_m", "RMSE aligned (m)"),
    ("median_aligned_m", "median aligned (m)"),
    ("p95_aligned_m", "p95 aligned (m)"),
    ("rotation_deg", "alignment rotation (deg)"),
    ("rmse_2001_7249_m", "RMSE scans 2001-7249 (m)"),
    ("fixes_vouched", "fixes the odometry vouches for"),
    ("rmse_vouched_m", "RMSE (m)"),
    ("median_vouched_m", "median (m)"),
    ("p95_vouched_m", "p95 (m)"),
    ("rmse_rfs_m", "RMSE, fixes within 25 ms of a scan (m)"),
    ("landmarks", "landmarks"),
    ("reference_trees_1m", "reference trees within 1 m"),
    ("precision_1m", "landmarks within 1 m of a reference tree"),
    ("false_detection_rate", "false detection rate"),
    ("close_pairs", "landmark pairs within 1.5 m"),
    ("one_tree_pairs", "of them one tree (reference or laser)"),
    ("precision_1_1000", "precision, landmarks of scans 1-1000"),
    ("precision_1001_2000", "precision, landmarks of scans 1001-2000"),
    ("false_detection_rate_1_1000", "false detection rate, scans 1-1000"),
    ("false_detection_rate_1001_2000", "false detection rate, scans 1001-2000"),
    ("nis_inside", "NIS inside 95% bounds"),
    ("circles_per_scan", "circles per scan"),
    ("published_matched", "published detections matched"),
    ("seconds", "seconds"),
    ("ms_per_scan", "ms per scan"),
    ("closure_matches", "constellation matches tried"),
    ("closure_refused_jc", "refused: not jointly compatible"),
    ("closures_accepted", "closures accepted"),
    ("landmarks_merged", "landmarks merged"),
    ("duplicates_merged", "duplicates swept"),
    *((k, v.replace(", m^2", " (m^2)").replace(", m", " (m)")) for k, v in GOSPA_LABELS.items()),
]


# victoria_park.md: the columns of the CSV (all but run and source) as narrow tables, by concern
PARTS = (
    ("Distance to GPS (all fixes, as estimated)", ("scans", "rmse_m", "median_m", "p95_m")),
    (
        "Distance to GPS without jumps, after alignment, and on the unseen part",
        (
            "rmse_clean_m",
            "rmse_aligned_m",
            "median_aligned_m",
            "p95_aligned_m",
            "rotation_deg",
            "rmse_2001_7249_m",
        ),
    ),
    (
        "Distance to the GPS fixes the odometry vouches for",
        ("fixes_vouched", "rmse_vouched_m", "median_vouched_m", "p95_vouched_m"),
    ),
    ("Distance to GPS under the RFS protocol (fixes within 25 ms of a scan)", ("rmse_rfs_m",)),
    (
        "Map and consistency",
        ("landmarks", "reference_trees_1m", "precision_1m", "false_detection_rate", "nis_inside"),
    ),
    ("Trees mapped twice (landmark pairs within 1.5 m)", ("close_pairs", "one_tree_pairs")),
    (
        "Map quality on each half of scans 1-2000",
        (
            "precision_1_1000",
            "precision_1001_2000",
            "false_detection_rate_1_1000",
            "false_detection_rate_1001_2000",
        ),
    ),
    (
        "Extraction and run time",
        ("circles_per_scan", "published_matched", "seconds", "ms_per_scan"),
    ),
    (
        "Loop closure (runs with [closure] enabled)",
        (
            "closure_matches",
            "closure_refused_jc",
            "closures_accepted",
            "landmarks_merged",
            "duplicates_merged",
        ),
    ),
    *(
        (
            f"GOSPA against the reference trees, c = {c:g} m (landmarks of scans 1-2000)",
            tuple(k for k in GOSPA_LABELS if k.startswith(f"gospa_{c:g}m")),
        )
        for c, _, _ in GOSPA_SETTINGS
    ),
)


def table_records(rows: list[dict]) -> list[dict]:
    """The table's records: our runs (`vp_trial`'s rows, in their order). The published
    figures are in their own table (`PUBLISHED_TABLE`)."""
    return [{"source": "ours", **{k: r.get(k) for k, _ in COLUMNS}} for r in rows]


def published_records(_rows=None) -> list[dict]:
    """The published figures (`PUBLISHED`), one record each, with where each comes from."""
    return [{"source": "published", **row} for row in PUBLISHED]


def _notes(rows: list[dict]) -> str:
    return (
        "GPS: every fix in the run's time span matched to the pose interpolated at its time, at "
        "the antenna (the laser, (3.78, 0.50) m in the vehicle frame); jumps (fixes implying "
        f"more than 1.25 x the top odometry speed) flagged ({rows[0]['jumps']} in the full run) "
        "and left in the RMSE columns, out of the 'without jumps' and the aligned ones. Aligned: "
        "after the rigid 2D transform fitted to the fixes. The RMSE of scans 2001-7249 covers "
        "only the fixes after scan 2000, the part the calibration never saw. NIS inside: the "
        "share of the scans with an update (scans predicted only, at rest, have none). "
        "Reference trees: "
        "the 2002 SLAM school's map of the 145 trees of scans 1-2000, in our frame by fitting "
        "its laser path to ours; landmarks within 1 m of a reference tree: the precision of "
        "the map, over the landmarks that joined it in scans 1-2000. False detection rate: "
        "the share of the circles the filter considered (in range, in scans it used) that no "
        "landmark of the final map explains (experiments/eval/map_quality.py; the paper's "
        "Table 4 figure without truth labels). Landmark pairs within 1.5 m: of the final "
        "map; one tree: both within 1 m of the same reference tree, or never both updated "
        "in one scan (the laser never saw them as two). GOSPA (p = 2, alpha = 2; c = 1 m, "
        "and the c = 20 m of the RFS-SLAM papers): the landmarks that joined in scans 1-2000 "
        "against all 145 reference trees (as aligned above), with its localisation, missed "
        "and false parts in m^2, which add up to its square (experiments/eval/gospa.py). "
        "Configuration: the victoria_park_ute "
        "preset (experiments/presets/victoria_park_ute.toml). The "
        "published figures, from other set-ups, are in victoria_park_published.md. Vouched "
        "fixes: those the wheel odometry alone agrees with over +-10 s "
        "(experiments/eval/vouched.py; no SLAM output enters the "
        "choice, so every run is scored on the same fixes). Within 25 ms: every fix within 25 "
        "ms of a scan time, none dropped, against the pose interpolated at the fix (the "
        "published random-finite-set protocol's time rule only; victoria-park-rfs runs that "
        "protocol whole). The first row's run is the one "
        "recorded in victoria_park.rrd; its seconds leave out the time spent in the recording "
        "calls."
    )


# victoria_park.md/.csv, from the rows of the runs (`vp_trial`)
TABLE = TableSpec(
    "victoria_park",
    table_records,
    index=("source", "run"),
    values=tuple(k for k, _ in COLUMNS[1:]),
    parts=PARTS,
    labels=dict(COLUMNS),
    title="Victoria Park: EKF-SLAM against GPS",
    notes=_notes,
)

# victoria_park_published.md/.csv: the published figures, once, with their sources
PUBLISHED_TABLE = TableSpec(
    "victoria_park_published",
    published_records,
    index=("source", "run", "protocol", "reference"),
    values=tuple(PUBLISHED_COLUMNS),
    labels={**PUBLISHED_COLUMNS, "reference": "where it comes from"},
    title="Victoria Park: published figures and where they come from",
    notes="Each figure as its source gives it (the README of the repository named, at the "
    "commit named; a figure that changed between commits is given with its history). Their "
    "set-ups differ from ours and from each other: detectors, starts, tuning and scoring. RFS "
    "protocol: the published random-finite-set protocol (experiments/eval/rfs_protocol.py; "
    "our run under it: victoria_park_rfs.md). Left out for want of a source: a 'PHD-SLAM "
    "2.5-4.4 m' and an 'EKF + JCBB, 1686 landmarks' row of earlier tables.",
)


def _antenna_path(lg) -> np.ndarray:
    """(N, 2) the run's antenna positions, world frame."""
    return np.array([se2.compose(p, lg.antenna_pose)[:2] for p in lg.pose])


def _closure_map(lg, seq) -> bytes:
    """vp_closures.png: a run with loop closure, where each constellation match was tried
    and how it ended."""
    from experiments.paper.victoria_park import figures

    ant = _antenna_path(lg)
    matches = [(ant[e["scan"]], e["outcome"]) for e in lg.closures]
    title = "Victoria Park with loop closure: the constellation matches tried, by outcome"
    return products.png(
        figures.plot_closure_map, seq.gps_xy, ant, lg.landmark_xy, matches, title=title
    )


def _figures(label: str, lg, sc, full) -> dict[str, bytes]:
    """vp_map.png and vp_timeseries.png of the run `lg` (scored `sc`) over `full`, as bytes."""
    from experiments.paper.victoria_park import figures

    ant = _antenna_path(lg)
    title = "Victoria Park: estimated antenna path and map over the GPS fixes"
    vp_map = products.png(figures.plot_vp_map, full.gps_xy, {label: ant}, lg.landmark_xy, title)
    t_end = float(full.scan_t[-1])
    gaps = [
        (a, min(b, t_end))
        for a, b in zip(full.gps_t[:-1], full.gps_t[1:])
        if b - a > GPS_GAP_S and a < t_end
    ]
    inside = np.full(lg.n_scans, np.nan)
    ok = np.flatnonzero(lg.scan_nis_dof > 0)
    inside[ok] = nis_inside(lg)
    # share of the last 100 scans with an update whose NIS was inside (NaN before the first)
    valid = np.isfinite(inside)
    c_in = np.concatenate([[0.0], np.cumsum(np.where(valid, inside, 0.0))])
    c_n = np.concatenate([[0], np.cumsum(valid)])
    k = np.arange(lg.n_scans)
    lo = np.maximum(0, k - 99)
    n_in, n_up = c_in[k + 1] - c_in[lo], c_n[k + 1] - c_n[lo]
    window = np.where(n_up > 0, n_in / np.maximum(n_up, 1), np.nan)
    part = "full run" if full.n_scans == VP_N_SCANS else f"first {full.n_scans} scans"
    title = f"Victoria Park, {part} (IHGR)"
    errors, sizes = {label: sc.errors}, {label: lg.n_map}
    timeseries = products.png(
        figures.plot_vp_timeseries,
        sc.t_s,
        errors,
        jumps=sc.jump,
        gaps=gaps,
        scan_t=lg.scan_t,
        nis_in=window,
        map_size=sizes,
        title=title,
        gap_s=GPS_GAP_S,
    )
    return {"vp_map.png": vp_map, "vp_timeseries.png": timeseries}
