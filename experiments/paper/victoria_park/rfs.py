"""Experiment `victoria-park-rfs`: the full Victoria Park run under the published
random-finite-set protocol, exactly (`experiments.eval.rfs_protocol`: PHD-SLAM 3.0 and
GM-PHD-PMAU-SLAM's Victoria Park set-up, read in their code), beside the same run without
clutter and the run of `victoria-park`, each also scored on the fixes the odometry vouches for.

The input: the tree detector on the raw laser where the raw laser exists (scans 1-2000: our
`bailey`, the reimplementation of the original detector), the detections published with the
data after that (scans 2001-7249: the original detector's output; their raw laser is not
public in the form we read), cut to 50 m and +-85 deg; Poisson clutter with mean 5 added to
every scan with detections, from the draw's seed; the filter started at the published fixed
start with zero covariance. The filter is the `victoria_park_ute` preset (IHGR), unchanged.

Rows (`ROWS`): the protocol with clutter, pooled over its draws (100; --quick: `QUICK_DRAWS`
draws, still over the whole run); the protocol without clutter (one run); the run of
`victoria-park` (the published detections uncut, the preset's GPS-fitted start). Every row
is scored on the same scans: those where the protocol's detector found a tree. Writes
victoria_park_rfs.md/.csv (the summary) and victoria_park_rfs_draws.md/.csv (one row per
run). The runs are trials on
the executor (local processes, or Dask with --dask); each draw is one trial.
"""

from __future__ import annotations

import dataclasses
import functools
import logging
import time

import numpy as np

from experiments.errors import MissingDataError
from experiments.eval.gps import fixes_in_run, score_sequence
from experiments.eval.rfs_protocol import (
    RfsProtocol,
    fov_cut,
    poisson_clutter,
    pooled_rmse,
    score_at_scans,
)
from experiments.eval.vouched import vouched_for_sequence
from experiments.exec import spawn_seeds
from experiments.io.writers import json_types
from experiments.paper import products
from experiments.paper.products import TableSpec
from experiments.paper.registry import experiment
from experiments.paper.runner import experiment_seed
from experiments.paper.victoria_park.real_run import PRESET, run_config
from slam import run_slam, se2

__all__ = [
    "NAME",
    "PROTOCOL",
    "QUICK_DRAWS",
    "ROWS",
    "protocol_input",
    "rfs_trial",
    "run",
    "start_prior",
    "summary_records",
]

log = logging.getLogger(__name__)

NAME = "victoria-park-rfs"
PROTOCOL = RfsProtocol()
QUICK_DRAWS = 10  # --quick: the draws; the runs still cover the whole run
# row kind -> its label in the tables
ROWS = {
    "clutter": "published protocol: detector cut to 50 m and +-85 deg, Poisson clutter 5 per "
    "scan, fixed start",
    "no clutter": "the same without clutter",
    "victoria-park": "victoria-park's run: published detections uncut, the preset's GPS start",
}


@dataclasses.dataclass(frozen=True)
class ProtocolInput:
    """The protocol's input: `seq` the full run with the detector's detections cut to the
    field of view (scans 1-`raw_scans` from the raw laser, the published ones after);
    `detected` (N,) bool, the scans where the detector found a tree before the cut (the scans
    clutter is added to and scored at); `full` the run as loaded."""

    seq: object
    detected: np.ndarray
    full: object
    raw_scans: int


def protocol_input(full, raw, cfg, protocol: RfsProtocol = PROTOCOL) -> ProtocolInput:
    """The detector's detections of the run `full`: the `bailey` extractor with `cfg`'s
    parameters for it on the raw scans
    of `raw` (its first scans, at the same times), the published detections of `full` on the
    later scans; cut to the protocol's field of view. No clutter."""
    from features import extract_features

    n_raw = min(raw.n_scans, full.n_scans)
    if not np.array_equal(raw.scan_t[:n_raw], full.scan_t[:n_raw]):
        raise MissingDataError("Victoria Park: the raw scans' times differ from the full run's")
    params, options = cfg.with_(**{"features.method": "bailey"}).features.extractor_args()
    scan, rng_m, bearing, radius = [], [], [], []
    for k in range(n_raw):
        c = extract_features(raw.scan(k), "bailey", params, **options).circle_params
        scan.append(np.full(c.shape[0], k))
        rng_m.append(np.hypot(c[:, 0], c[:, 1]))
        bearing.append(np.arctan2(c[:, 1], c[:, 0]))
        radius.append(c[:, 2])
    late = full.det_scan >= n_raw
    scan.append(full.det_scan[late])
    rng_m.append(full.det_range[late])
    bearing.append(full.det_bearing[late])
    radius.append(full.det_radius[late])
    scan, rng_m, bearing, radius = (np.concatenate(x) for x in (scan, rng_m, bearing, radius))
    detected = np.bincount(scan.astype(np.int64), minlength=full.n_scans) > 0
    keep = fov_cut(rng_m, bearing, protocol)
    seq = _with_detections(full, scan[keep], rng_m[keep], bearing[keep], radius[keep])
    return ProtocolInput(seq, detected, full, n_raw)


def _with_detections(seq, scan, range_m, bearing, radius):
    """`seq` with its detections replaced (sorted by scan, stable)."""
    order = np.argsort(scan, kind="stable")
    return dataclasses.replace(
        seq,
        det_scan=np.asarray(scan, np.int64)[order],
        det_range=np.asarray(range_m, np.float64)[order],
        det_bearing=np.asarray(bearing, np.float64)[order],
        det_radius=np.asarray(radius, np.float64)[order],
        det_cov=None,
    )


def with_clutter(inp: ProtocolInput, rng: np.random.Generator, protocol: RfsProtocol = PROTOCOL):
    """The protocol's input with one draw of clutter (`poisson_clutter`) on every scan where
    the detector found a tree; a false detection's radius is unknown (NaN)."""
    s = inp.seq
    c_scan, c_range, c_bearing = poisson_clutter(rng, np.flatnonzero(inp.detected), protocol)
    return _with_detections(
        s,
        np.concatenate([s.det_scan, c_scan]),
        np.concatenate([s.det_range, c_range]),
        np.concatenate([s.det_bearing, c_bearing]),
        np.concatenate([s.det_radius, np.full(c_scan.size, np.nan)]),
    ), int(c_scan.size)


def start_prior(laser_pose, protocol: RfsProtocol = PROTOCOL) -> tuple[np.ndarray, np.ndarray]:
    """(vehicle pose (3,), zero covariance (3, 3)): the rear-axle pose that puts the laser
    (`laser_pose` in the vehicle frame) at the published start, position and heading. Their
    state is the laser's pose: `h_func` measures from it and its heading (their model has no
    laser yaw), so with our calibrated yaw the vehicle's heading is the start's minus it."""
    x, y, heading = protocol.start_laser
    laser = np.asarray(laser_pose, np.float64)
    vehicle_heading = heading - laser[2]
    offset = se2.rotate(vehicle_heading, laser[:2].reshape(1, 2))[0]
    return np.array([x - offset[0], y - offset[1], vehicle_heading]), np.zeros((3, 3))


@functools.cache
def _data(quick: bool):
    """(protocol input, the preset), read once per process (quick or not: the whole run)."""
    from experiments.io.victoria_park import load_victoria_park

    full = load_victoria_park(full=True)
    raw = load_victoria_park()
    cfg = run_config("detections", "ihgr")
    return protocol_input(full, raw, cfg), cfg


def rfs_trial(job: tuple, seed=None) -> dict:
    """One run (`job` = (kind, draw, quick), kind a key of `ROWS`): the clutter draws use
    `seed`; the others are deterministic. Returns its row: the per-scan errors under the
    protocol (`errors`, NaN where no fix is within 25 ms), their RMSE, the vouched and the
    within-25-ms-of-a-scan RMSE of `experiments.eval.gps`, landmarks, clutter, seconds."""
    kind, draw, quick = job
    inp, cfg = _data(quick)
    clutter = 0
    if kind == "victoria-park":
        seq, prior = inp.full, None
    else:
        seq = inp.seq
        if kind == "clutter":
            seq, clutter = with_clutter(inp, np.random.default_rng(seed))
        prior = start_prior(cfg.vehicle.laser_pose)
    t0 = time.perf_counter()
    lg = run_slam(seq, cfg, prior=prior)
    seconds = time.perf_counter() - t0
    laser = np.array([se2.compose(p, lg.antenna_pose)[:2] for p in lg.pose])
    scored = np.flatnonzero(inp.detected[: lg.n_scans])
    # the fixes are chosen by the scans' own stamps (the run's scan_t are its poses' times,
    # earlier by the preset's laser latency, if any)
    errors = score_at_scans(seq.scan_t[scored], laser[scored], seq.gps_t, seq.gps_xy)
    sc = score_sequence(seq, lg.scan_t, lg.pose, lg.antenna_pose, _vouched(seq, cfg))
    return {
        "kind": kind,
        "run": ROWS[kind],
        "draw": draw,
        "errors": errors,
        "rmse_protocol_m": pooled_rmse([errors]),
        "scans_scored": int(np.isfinite(errors).sum()),
        "rmse_vouched_m": sc.vouched_rmse,
        "vouched_errors": sc.errors[_vouched(seq, cfg)[fixes_in_run(seq.gps_t, lg.scan_t)]],
        "rmse_rfs_m": sc.rfs_rmse,
        "landmarks": int(lg.landmark_xy.shape[0]),
        "clutter": clutter,
        "start": lg.start,
        "seconds": seconds,
    }


def _vouched(seq, cfg) -> np.ndarray:
    key = (seq.n_scans, float(seq.gps_t[0]))
    if key not in _VOUCHED:
        _VOUCHED[key] = vouched_for_sequence(seq, cfg)
    return _VOUCHED[key]


_VOUCHED: dict = {}


def summary_records(rows: list[dict]) -> list[dict]:
    """The summary table: one record per kind of run, its errors pooled over its runs (the
    protocol's RMSE over every scored scan of every draw; the vouched RMSE over every vouched
    fix of every draw), and the spread of the runs' own figures."""
    out = []
    for kind, label in ROWS.items():
        got = [r for r in rows if r["kind"] == kind]
        if not got:
            continue
        per_run = np.array([r["rmse_protocol_m"] for r in got])
        out.append(
            {
                "run": label,
                "runs": len(got),
                "rmse_protocol_m": pooled_rmse([r["errors"] for r in got]),
                "rmse_protocol_min_m": float(per_run.min()),
                "rmse_protocol_max_m": float(per_run.max()),
                "scans_scored": int(np.mean([r["scans_scored"] for r in got])),
                "rmse_vouched_m": pooled_rmse([r["vouched_errors"] for r in got]),
                "rmse_rfs_m": float(np.sqrt(np.mean([r["rmse_rfs_m"] ** 2 for r in got]))),
                "landmarks": float(np.mean([r["landmarks"] for r in got])),
                "clutter_per_scan": float(np.mean([r["clutter"] for r in got]))
                / max(got[0]["errors"].size, 1),
                "seconds": float(np.mean([r["seconds"] for r in got])),
            }
        )
    return out


def draw_records(rows: list[dict]) -> list[dict]:
    """One record per run: its own figures (no per-scan arrays)."""
    keys = ("run", "draw", "rmse_protocol_m", "scans_scored", "rmse_vouched_m", "rmse_rfs_m")
    keys += ("landmarks", "clutter", "seconds")
    return [{k: r[k] for k in keys} for r in rows]


SUMMARY_COLUMNS = {
    "runs": "runs (draws)",
    "rmse_protocol_m": "RMSE, the protocol, pooled (m)",
    "rmse_protocol_min_m": "RMSE of a run, lowest (m)",
    "rmse_protocol_max_m": "RMSE of a run, highest (m)",
    "scans_scored": "scans scored (a fix within 25 ms)",
    "rmse_vouched_m": "RMSE, vouched fixes, pooled (m)",
    "rmse_rfs_m": "RMSE, fixes within 25 ms of a scan (m)",
    "landmarks": "landmarks (mean)",
    "clutter_per_scan": "false detections added per scan with detections",
    "seconds": "seconds per run",
}
DRAW_COLUMNS = {
    "draw": "draw",
    "rmse_protocol_m": "RMSE, the protocol (m)",
    "scans_scored": "scans scored",
    "rmse_vouched_m": "RMSE, vouched fixes (m)",
    "rmse_rfs_m": "RMSE, fixes within 25 ms of a scan (m)",
    "landmarks": "landmarks",
    "clutter": "false detections added",
    "seconds": "seconds",
}


def _notes(rows: list[dict]) -> str:
    draws = sum(r["kind"] == "clutter" for r in rows)
    scans = rows[0]["errors"].size if rows else 0
    return (
        "The published random-finite-set protocol of PHD-SLAM 3.0 and GM-PHD-PMAU-SLAM, read in "
        "their code (experiments/eval/rfs_protocol.py names the files and commits): the tree "
        "detector's detections cut to 50 m and +-85 deg; Poisson clutter, mean 5, range and "
        "bearing uniform over that field of view, added to every scan with detections; the "
        "start fixed: the laser at (-67.6493, -41.7142) m, heading 35.5 deg, zero covariance; "
        "each scan with detections scored at the laser against the GPS fix nearest in time "
        "when it is within 25 ms; the RMSE pooled over every scored scan of every draw "
        f"({draws} draws here; {scans} scans with detections). Detector: ours (`bailey`, the "
        "reimplementation of the original detector) on the raw laser of scans 1-2000, the "
        "published detections (the original detector's output) on scans 2001-7249, where "
        "the raw laser is not available to us. Filter: the victoria_park_ute preset, "
        "unchanged (IHGR). Vouched: the fixes the wheel odometry vouches for "
        "(experiments/eval/vouched.py), pooled likewise. Within 25 ms of a scan: the rule of "
        "the victoria-park table (every fix within 25 ms of a scan time, against the pose "
        "interpolated at the fix)."
    )


SUMMARY = TableSpec(
    "victoria_park_rfs",
    summary_records,
    index=("run",),
    values=tuple(SUMMARY_COLUMNS),
    labels=SUMMARY_COLUMNS,
    title="Victoria Park under the published RFS protocol, exactly",
    notes=_notes,
)
DRAWS = TableSpec(
    "victoria_park_rfs_draws",
    draw_records,
    index=("run", "draw"),
    values=tuple(k for k in DRAW_COLUMNS if k != "draw"),
    labels=DRAW_COLUMNS,
    title="Victoria Park under the published RFS protocol: each run",
    notes=_notes,
)


@experiment(
    "victoria-park-rfs",
    order=70,
    page="victoria-park-rfs.md",
    help="the full run under the published RFS protocol, exactly (100 clutter draws; only "
    "when named)",
    default=False,
)
def run(ctx) -> None:
    """The registered experiment `victoria-park-rfs`: each run a trial on the executor (the
    clutter draws with seeds spawned from the experiment's); the tables are written after the
    other experiments have started (`RunContext.later`)."""
    try:
        from experiments.io.victoria_park import load_victoria_park

        load_victoria_park(n_scans=1)
    except MissingDataError as exc:
        log.warning("Victoria Park RFS experiment skipped: %s", exc)
        ctx.config[NAME] = f"skipped: {exc}"
        return
    draws = QUICK_DRAWS if ctx.quick else PROTOCOL.draws
    ctx.config[NAME] = {
        "preset": PRESET,
        "protocol": json_types(dataclasses.asdict(PROTOCOL)),
        "draws": draws,
    }
    jobs = [("no clutter", 0, ctx.quick), ("victoria-park", 0, ctx.quick)]
    jobs += [("clutter", d + 1, ctx.quick) for d in range(draws)]
    seeds = [None, None] + spawn_seeds(experiment_seed(ctx.seed, NAME), draws)
    batch = ctx.submit(rfs_trial, jobs, seeds, desc="victoria park rfs runs", chunksize=1)

    def finish(rows: list[dict]) -> None:
        order = {k: i for i, k in enumerate(ROWS)}
        rows = sorted(rows, key=lambda r: (order[r["kind"]], r["draw"]))
        products.tables(ctx, [SUMMARY, DRAWS], rows)

    ctx.later(batch, finish)
