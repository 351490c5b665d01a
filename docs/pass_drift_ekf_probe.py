"""Probe behind the lab notebook's entry "The EKF with a pass offset that drifts with the view
angle": the Victoria Park preset (published detections) with the pass offset as a state of the
filter, Gauss-Markov in the view angle, s the leave-one-pass-out s and L the within-pass
semivariogram's (both derived on scans 1-2000, `experiments.eval.pass_offsets`,
`experiments.eval.pass_drift`), then the smoother with the same model on each run's log.

    TRUNKSLAM_DATA=../shared/datasets PYTHONPATH=. .venv/bin/python \
        docs/pass_drift_ekf_probe.py 0.0584 2000 on off

WHICH: 2000 (scans 1-2000), on / off (the full run, loop closure on / off). Diagnosis only:
nothing here sets a default.
"""

import sys
import time

import numpy as np
from threadpoolctl import threadpool_limits

from experiments.eval.gps import score_sequence
from experiments.eval.vouched import vouched_for_sequence
from experiments.io.config_file import load_slam_config
from experiments.io.victoria_park import load_victoria_park
from experiments.paper.victoria_park.real_run import head
from slam import run_slam
from slam.smoother import SmootherOptions, problem_from_log, smooth

S = (0.0546, 0.0385)  # m: the leave-one-pass-out s (range, across), scans 1-2000


def main(L: float, runs: list[str]) -> None:
    """The EKF and the smoother on each run of `runs`, the drift's length L (rad)."""
    with threadpool_limits(1):
        full = load_victoria_park(full=True)
        for which in runs:
            seq = head(full, 2000) if which == "2000" else full
            cfg = load_slam_config("victoria_park_ute").with_(
                **{
                    "features.method": "detections",
                    "closure.enabled": which == "on",
                    "measurement.pass_offset_sd_m": S,
                    "measurement.pass_offset_model": "state",
                    "measurement.pass_offset_corr_rad": L,
                }
            )
            t0 = time.process_time()
            log = run_slam(seq, cfg)
            dt = time.process_time() - t0
            v = vouched_for_sequence(seq, cfg)
            sc = score_sequence(seq, log.scan_t, log.pose, log.antenna_pose, vouched=v)
            ok = np.isfinite(log.scan_nis)
            nis = float(log.scan_nis[ok].sum() / max(1, log.scan_nis_dof[ok].sum()))
            print(
                f"{which} L={L}: EKF {sc.vouched_rmse:.3f} vouched {sc.rfs_rmse:.3f} RFS, "
                f"landmarks {log.landmark_id.size}, nis/dof {nis:.3f}, {dt:.0f} s CPU",
                flush=True,
            )
            r = smooth(problem_from_log(log), SmootherOptions(marginals=False))
            sc = score_sequence(seq, log.scan_t, r.pose, log.antenna_pose, vouched=v)
            print(
                f"{which} L={L}: smoother {sc.vouched_rmse:.3f} vouched {sc.rfs_rmse:.3f} RFS, "
                f"chi2/dof {r.chi2_per_dof:.3f}, pass vars {r.pass_variables}",
                flush=True,
            )


if __name__ == "__main__":
    main(float(sys.argv[1]), sys.argv[2:])
