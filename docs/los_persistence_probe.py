"""Probe behind the lab notebook's entry "A trunk's line-of-sight offset belongs to the pass, not
to the tree": whether the offset of a trunk's fitted centre along the line of sight persists from
one pass to the next (a per-tree state, such as an error in the detector's radius, would), on the
full Victoria Park run (VP preset, published detections, IHGR, closure off).

    TRUNKSLAM_DATA=../shared/datasets PYTHONPATH=. .venv/bin/python docs/los_persistence_probe.py

Prints (one full run and a fit per pass, under a minute on one core):

1. Per pass of a landmark (sightings less than `PASS_GAP_S` apart, at least `MIN_SIGHTINGS`,
   the line of sight turning by at least `MIN_TURN_DEG`), its sightings' world points through
   the filter's poses fitted as w_j = c + b u_j (u_j the unit line of sight from the laser): the
   mean and spread of b on scans 1-2000 (t < 450 s) and after, with the fit's standard error.
2. Persistence: the correlation of b between two passes of one landmark, and the spread of b
   split into the part shared by a landmark's passes and the part of each pass (passes with a
   standard error under `WELL_DETERMINED_M`).
3. The same passes pooled (`experiments.eval.trace_bias.trace_fit`), each with its own centre,
   with four terms shared by all: a range offset b0, an offset p0 across the line of sight, a
   bearing scale e and a range scale g, on scans 1-2000 and after (passes that end by 450 s,
   and those after).
4. With `--scales e1,e2,...`: the full run again with every bearing multiplied by 1 + e, the
   pooled fit of scans 1-2000 on it, and its RMSE on the vouched GPS fixes (a minute per run).

Diagnosis only: nothing here sets a default.
"""

from __future__ import annotations

import argparse
import dataclasses

import numpy as np
from threadpoolctl import threadpool_limits

from experiments.eval.gps import score_sequence
from experiments.eval.trace_bias import sight_lines, trace_fit, trace_passes
from experiments.eval.vouched import vouched_for_sequence
from experiments.io.victoria_park import load_victoria_park
from experiments.paper.victoria_park.real_run import run_config
from slam import run_slam

PASS_GAP_S = 2.0  # s: `measurement.pass_gap_s`, the pass of the pass-offset model
MIN_SIGHTINGS = 6  # a pass needs this many sightings to fit c and b
MIN_TURN_DEG = 30.0  # deg: the line of sight must turn this much to tell b from c
WELL_DETERMINED_M = 0.05  # m: standard error of b under which a pass enters the split


def line_of_sight_fit(w: np.ndarray, u: np.ndarray) -> tuple[float, float]:
    """Least squares w_j = c + b u_j over one pass: (b, its standard error)."""
    n = len(w)
    A = np.zeros((2 * n, 3))
    A[0::2, 0] = A[1::2, 1] = 1.0
    A[0::2, 2], A[1::2, 2] = u[:, 0], u[:, 1]
    y = w.ravel()
    x = np.linalg.lstsq(A, y, rcond=None)[0]
    e = y - A @ x
    cov_b = np.linalg.inv(A.T @ A)[2, 2] * (e @ e) / max(2 * n - 3, 1)
    return float(x[2]), float(np.sqrt(cov_b))


def pass_offsets(log) -> np.ndarray:
    """One row per pass that qualifies: (landmark, start time s, b m, se m)."""
    w, u = sight_lines(log)
    t, lm = log.scan_t[log.obs_scan], log.obs_landmark
    passes = trace_passes(log, gap_s=PASS_GAP_S, min_sightings=MIN_SIGHTINGS,
                          min_turn_rad=np.radians(MIN_TURN_DEG))  # fmt: skip
    return np.array([(lm[p[0]], t[p[0]], *line_of_sight_fit(w[p], u[p])) for p in passes])


def fit_words(f) -> str:
    return (
        f"b0 {100 * f.range_offset_m:+.2f} cm (se {100 * f.se[0]:.2f}), p0 "
        f"{100 * f.across_offset_m:+.2f} cm (se {100 * f.se[1]:.2f}), bearing scale e "
        f"{100 * f.bearing_scale:+.3f}% (se {100 * f.se[2]:.3f}), range scale g "
        f"{100 * f.range_scale:+.3f}% (se {100 * f.se[3]:.3f})"
    )


def print_pooled(log) -> None:
    for lo, hi, name in ((0, 450, "scans 1-2000"), (450, np.inf, "after")):
        f = trace_fit(log, lo, hi)
        print(f"pooled, {name} ({f.passes} passes): {fit_words(f)}")


def print_scaled(seq, cfg, scales: list[float]) -> None:
    vouched = vouched_for_sequence(seq, cfg)
    for e in scales:
        scaled = dataclasses.replace(seq, det_bearing=seq.det_bearing * (1.0 + e))
        log = run_slam(scaled, cfg)
        rmse = score_sequence(scaled, log.scan_t, log.pose, log.antenna_pose, vouched=vouched)
        print(
            f"bearings x (1 {e:+.4f}): pooled on scans 1-2000 {fit_words(trace_fit(log, 0, 450))}"
            f"; full run {rmse.vouched_rmse:.3f} m vouched"
        )


def print_spread(R: np.ndarray) -> None:
    print(f"{len(R)} passes, {np.unique(R[:, 0]).size} landmarks")
    for lo, hi, name in ((0, 450, "scans 1-2000"), (450, np.inf, "after")):
        q = (R[:, 1] >= lo) & (R[:, 1] < hi)
        print(
            f"{name}: b mean {100 * R[q, 2].mean():+.1f} cm, sd {100 * R[q, 2].std():.1f} cm, "
            f"median se {100 * np.median(R[q, 3]):.1f} cm, {q.sum()} passes"
        )


def print_persistence(R: np.ndarray) -> None:
    pairs = []
    for landmark in np.unique(R[:, 0]):
        q = np.flatnonzero(R[:, 0] == landmark)
        pairs += [(R[i, 2], R[j, 2]) for k, i in enumerate(q) for j in q[k + 1 :]]
    a, b = np.array(pairs).T
    print(
        f"{len(a)} pairs of passes of one landmark: correlation of b {np.corrcoef(a, b)[0, 1]:.3f}"
    )
    ok = R[R[:, 3] < WELL_DETERMINED_M]
    ids, inverse, counts = np.unique(ok[:, 0], return_inverse=True, return_counts=True)
    multi = counts[inverse] >= 2
    means = np.bincount(inverse, ok[:, 2]) / counts
    within = ok[multi, 2] - means[inverse][multi]
    dof = multi.sum() - (counts >= 2).sum()
    total, per_pass = ok[multi, 2].var(), (within @ within) / dof
    noise = np.median(ok[multi, 3]) ** 2
    print(
        f"{multi.sum()} well-determined passes of {(counts >= 2).sum()} landmarks: sd of b "
        f"{100 * np.sqrt(total):.1f} cm = shared by the landmark "
        f"{100 * np.sqrt(max(total - per_pass, 0)):.1f} cm (+) each pass's "
        f"{100 * np.sqrt(per_pass):.1f} cm, of which the fit's noise {100 * np.sqrt(noise):.1f} cm"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scales", default="", help="part 4: comma-separated bearing scales e")
    args = ap.parse_args()
    threadpool_limits(1)
    seq, cfg = load_victoria_park(full=True), run_config("detections", "ihgr")
    log = run_slam(seq, cfg)
    R = pass_offsets(log)
    print_spread(R)
    print_persistence(R)
    print_pooled(log)
    if args.scales:
        print_scaled(seq, cfg, [float(v) for v in args.scales.split(",")])


if __name__ == "__main__":
    main()
