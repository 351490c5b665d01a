"""`trunkslam bench slam`: EKF-SLAM time per scan against the size of the map.

The map has to grow to hundreds of landmarks, which the tree park cannot give, so the bench
drives the filter down a long avenue (`experiments.sim.landmarks.avenue`): trees on both sides
of a straight road, 5 Hz scans and 20 Hz odometry with the Cycab noise, every tree ahead within
20 m measured as a circle centre with the `paper` noise model (the extractor itself is timed by
`trunkslam bench extract`). `slam.run_slam` times its phases per scan; the rows give their medians
over the scans whose map size falls in each bin. One process; numpy's BLAS may use more than
one thread for the larger matrices.
"""

from __future__ import annotations

import itertools
import os
import tempfile
import time
from pathlib import Path

import numpy as np

from experiments.io.config_file import load_slam_config
from experiments.io.provenance import machine
from experiments.io.writers import markdown_table
from experiments.sim.landmarks import avenue
from slam import TIMING_KEYS, run_slam

__all__ = ["bench", "bench_victoria_park", "format_table", "recorded_row", "records_table"]


BINS = (0, 25, 50, 100, 200, 300, 400, 600, 800, 1200)
# The recorded run's cost is measured over this many pairs (the plain run, then the recorded
# run): a shared machine's load changes while the bench runs, and a pair's two runs see about
# the same load.
RECORDING_PAIRS = 3


def _scans(progress, desc: str):
    """`slam.run_slam`'s progress callback (after each scan, outside its timed steps) as a
    progress(description, done, total), every 10 scans; None without `progress`."""
    if progress is None:
        return None

    def each(done: int, total: int) -> None:
        if done % 10 == 0 or done == total:
            progress(desc, done, total)

    return each


def bench(
    n_trees: int = 800, association: str = "ihgr", seed: int = 0, bins=BINS, progress=None
) -> list[dict]:
    """Median ms per scan of each phase, by map size (landmarks in the filter). progress:
    an optional callback(description, done, total), after each tenth scan."""
    seq, feats = avenue(n_trees, np.random.default_rng(seed))
    t0 = time.perf_counter()
    log = run_slam(
        seq,
        load_slam_config("cycab"),  # the avenue's car and circles are the simulated Cycab's
        features=feats,
        association=association,
        progress=_scans(progress, "slam, avenue"),
    )
    return _rows(log, time.perf_counter() - t0, bins, "avenue")


def bench_victoria_park(
    association: str = "ihgr", root=None, bins=BINS, progress=None
) -> list[dict]:
    """The full Victoria Park run (7249 scans, published detections, preset victoria_park_ute):
    the same rows, and the whole run's seconds (of a second run: the first loads the caches), at
    this process's threads (`trunkslam --threads`, default 1), once more with a rerun recording
    of every scan (`recorded_row`: its cost against the plain run's), with loop closure on
    (`[closure] enabled`), and once more without it with the BLAS at every core, the library's
    own default before commands set it."""
    from experiments.io.config_file import load_slam_config
    from experiments.io.victoria_park import load_victoria_park

    seq = load_victoria_park(root, full=True)
    cfg = load_slam_config("victoria_park_ute")
    cfg = cfg.with_(**{"features.method": "detections", "association.method": association})
    closure = cfg.with_(**{"closure.enabled": True})
    # the warm-up runs with closure: it loads (or compiles) every kernel both timed runs use
    run_slam(seq, closure, progress=_scans(progress, "slam, Victoria Park (warm-up)"))
    t0 = time.perf_counter()
    log = run_slam(seq, cfg, progress=_scans(progress, "slam, Victoria Park"))
    rows = _rows(log, time.perf_counter() - t0, bins, "Victoria Park")
    rows.append(recorded_row(seq, cfg, bins, progress))
    from threadpoolctl import threadpool_limits

    t0 = time.perf_counter()
    log = run_slam(seq, closure, progress=_scans(progress, "slam, Victoria Park, loop closure"))
    rows += _rows(log, time.perf_counter() - t0, bins, "Victoria Park, loop closure")[-1:]
    cores = os.cpu_count() or 1
    with threadpool_limits(limits=cores, user_api="blas"):
        t0 = time.perf_counter()
        log = run_slam(seq, cfg, progress=_scans(progress, f"slam, {cores} BLAS threads"))
        wall = time.perf_counter() - t0
    rows += _rows(log, wall, bins, f"Victoria Park, {cores} BLAS threads")[-1:]
    return rows


def recorded_row(seq, cfg, bins, progress, pairs: int = RECORDING_PAIRS) -> dict:
    """The whole-run row of the same run recorded as `trunkslam slam --rerun FILE` records it
    (`experiments.render.viz.Recorder`, every scan, the time series at the end, the file
    closed), and what the recording costs: `pairs` times the run without a recording, then
    with one; "recording ratio" and "recording CPU ratio": the medians over the pairs of the
    recorded run's wall seconds over the plain run's, and of its CPU seconds (this process's,
    rerun's own threads included) over the plain run's; "run seconds": the recorded runs'
    median wall seconds; the file's size; "load": the machine's 1-minute load average before
    and after the pairs (other processes share the cores)."""
    walls, ratios, cpu_ratios = [], [], []
    load_before = os.getloadavg()[0]
    for i in range(pairs):
        c0, t0 = time.process_time(), time.perf_counter()
        run_slam(seq, cfg, progress=_scans(progress, f"slam, Victoria Park, pair {i + 1}"))
        plain_cpu, plain_wall = time.process_time() - c0, time.perf_counter() - t0
        log, wall, cpu, size = _recorded(seq, cfg, progress, f"recorded, pair {i + 1}")
        walls.append(wall)
        ratios.append(wall / plain_wall)
        cpu_ratios.append(cpu / plain_cpu)
    row = _rows(log, float(np.median(walls)), bins, "Victoria Park, with a recording")[-1]
    row["recording ratio"] = round(float(np.median(ratios)), 2)
    row["recording CPU ratio"] = round(float(np.median(cpu_ratios)), 2)
    row["recording MiB"] = round(size / 2**20, 1)
    row["load"] = f"{load_before:.1f}-{os.getloadavg()[0]:.1f}"
    return row


def _recorded(seq, cfg, progress, desc: str):
    """(log, wall s, CPU s, file bytes) of the run recorded to a temporary file."""
    from experiments.eval.series import slam_panels, slam_series
    from experiments.render.viz import open_recording

    with tempfile.TemporaryDirectory(prefix="trunkslam-bench-") as tmp:
        path = Path(tmp) / "victoria_park.rrd"
        c0, t0 = time.process_time(), time.perf_counter()
        with open_recording(path, "slam", series=slam_panels(False)) as rec:
            log = run_slam(seq, cfg, visualiser=rec, progress=_scans(progress, desc))
            rec.log_series(log.scan_t, slam_series(log, seq.truth_t, seq.truth_pose))
        cpu, wall = time.process_time() - c0, time.perf_counter() - t0
        return log, wall, cpu, path.stat().st_size


def _rows(log, wall: float, bins, label: str) -> list[dict]:
    n_map = log.n_map
    rows = []
    for lo, hi in itertools.pairwise(bins):
        sel = (n_map >= lo) & (n_map < hi)
        if not sel.any():
            continue
        row = {
            "map size": f"{lo}-{hi - 1}",
            "scans": int(sel.sum()),
            "state dim": int(3 + 2 * np.median(n_map[sel])),
            "measurements": round(float(np.mean(log.n_features[sel])), 1),
        }
        for k in TIMING_KEYS:
            if k != "features":
                row[f"{k} ms"] = round(1e3 * float(np.median(log.timing_s[k][sel])), 3)
        rows.append(row)
    rows.append(
        {
            "map size": f"whole run ({label})",
            "scans": log.n_scans,
            "state dim": int(3 + 2 * n_map[-1]),
            "measurements": round(float(np.mean(log.n_features)), 1),
            "total ms": round(1e3 * wall / log.n_scans, 3),
            "run seconds": round(wall, 2),
        }
    )
    for r in rows[:-1]:
        r["map size"] = f"{label} {r['map size']}"
    return rows


def format_table(rows: list[dict]) -> str:
    return records_table("EKF-SLAM time per scan against map size", rows)


def records_table(title: str, rows: list[dict]) -> str:
    """`title (machine; ...)` over a Markdown table of `rows` (dicts; columns in order of first
    appearance, a missing key an empty cell): the bench tables' common form."""
    header = list(dict.fromkeys(k for r in rows for k in r))
    body = [[r.get(k, "") for k in header] for r in rows]
    return f"{title} ({machine()}; one process, `trunkslam --threads`)\n\n" + markdown_table(
        header, body
    )
