"""Probes behind the lab notebook's entry "The pass offset as a Gauss-Markov drift in the view
angle": the drift's derivation on scans 1-2000 and the smoother with it on the full run.

    TRUNKSLAM_DATA=../shared/datasets PYTHONPATH=. .venv/bin/python docs/pass_drift_probes.py

1. The derivation (no GPS, scans 1-2000 only): the white EKF run of the calibration's
   pass-offset step (the preset, published detections), its sightings' residuals about their
   landmark in their pass's first line of sight, the within-pass semivariogram against the
   view's turn and its Gauss-Markov fit (`experiments.eval.pass_drift`), over scans 1-2000 and
   each half, at the filter's poses and at the white smoother's.
2. The smoother on the EKF logs of docs/pass_state_probes.py (the inflation runs: scans
   1-2000, the full run with closure on and off; their associations), with (s, L) fixed by 1
   before any full-run score: white, the constant "state" (s = the leave-one-pass-out s), and
   the drifting state with L = 0.0584 rad and A: the within-pass fit's s = (0.0317, 0) m, C:
   the leave-one-pass-out s = (0.0546, 0.0385) m. Vouched and RFS RMSE beside the EKF's.
Diagnosis only: nothing here sets a default.
"""

from __future__ import annotations

import dataclasses
import sys
import time
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

from experiments.eval.gps import score_sequence
from experiments.eval.pass_drift import fit_drift, semivariogram, sightings_of
from experiments.io.config_file import load_slam_config
from experiments.io.victoria_park import load_victoria_park
from experiments.paper.victoria_park.real_run import head
from slam import run_slam
from slam.smoother import SmootherOptions, problem_from_log, smooth

L_RAD = 0.0584  # the derivation's shared L (scans 1-2000, white run, the filter's poses)
S_LOPO = (0.0546, 0.0385)  # the calibration's leave-one-pass-out s
VARIANTS = {
    "white": ((0.0, 0.0), "inflation", None),
    "state": (S_LOPO, "state", None),
    "drift A (within-pass fit)": ((0.0317, 0.0), "state", L_RAD),
    "drift C (LOPO s)": (S_LOPO, "state", L_RAD),
}


def derivation() -> None:
    seq = head(load_victoria_park(full=True), 2000)
    white = run_slam(seq, load_slam_config("victoria_park_ute"))
    smoothed = smooth(problem_from_log(white), SmootherOptions(marginals=False)).pose
    for label, pose in (("filter's poses", None), ("white smoother's poses", smoothed)):
        for lo, hi in ((0, 2000), (0, 1000), (1000, 2000)):
            s = sightings_of(white, hi, 2.0, pose, first_scan=lo)
            v = semivariogram(s)
            f = fit_drift(v)
            print(f"{label}, scans {lo + 1}-{hi}: L {f.corr_rad:.4f} rad, s {np.round(f.sd_m, 4)}"
                  f", r_eff sd {np.round(np.sqrt(f.r_eff_m2), 4)}, per-axis L "
                  f"{np.round(f.corr_axis_rad, 4)}, s from the sill {np.round(f.sd_between_m, 4)}"
                  f", {s.e.shape[0]} sightings")  # fmt: skip
            if (lo, hi) == (0, 2000):
                print("  pairs", v.pairs.tolist())
                print("  gamma cm^2 along", np.round(v.gamma[:, 0] * 1e4, 1).tolist())
                print("  gamma cm^2 across", np.round(v.gamma[:, 1] * 1e4, 1).tolist())
                print("  between-pass cm^2", np.round(v.between * 1e4, 1).tolist())


def under(log, sd, kind, corr):
    m = {**log.config["measurement"], "pass_offset_sd_m": list(sd), "pass_offset_model": kind}
    if corr is not None:
        m["pass_offset_corr_rad"] = corr
    return dataclasses.replace(log, config={**log.config, "measurement": m})


def measurement() -> None:
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from pass_state_probes import ekf_run  # the EKF runs of the h39s entry

    for label, n, closure in (("scans 1-2000", 2000, False), ("full run, closure on", None, True),
                              ("full run, closure off", None, False)):  # fmt: skip
        seq, log, vouched = ekf_run(n, closure)
        sc = score_sequence(seq, log.scan_t, log.pose, log.antenna_pose, vouched=vouched)
        print(f"{label}: EKF (inflation) {sc.vouched_rmse:.3f} / {sc.rfs_rmse:.3f} m")
        for name, (sd, kind, corr) in VARIANTS.items():
            t0 = time.perf_counter()
            r = smooth(
                problem_from_log(under(log, sd, kind, corr)), SmootherOptions(marginals=False)
            )
            sc = score_sequence(seq, log.scan_t, r.pose, log.antenna_pose, vouched=vouched)
            print(f"  {name:26s} {sc.vouched_rmse:.3f} / {sc.rfs_rmse:.3f} m, chi2/dof "
                  f"{r.chi2_per_dof:.3f}, variables {r.pass_variables}, "
                  f"{time.perf_counter() - t0:.1f} s")  # fmt: skip


if __name__ == "__main__":
    with threadpool_limits(1):
        derivation()
        measurement()
