"""Probe behind the lab notebook's entry "The full run's figure: how far it moves when nothing
that matters changes": the spread of the full Victoria Park run's vouched RMSE.

    TRUNKSLAM_DATA=../shared/datasets PYTHONPATH=. .venv/bin/python docs/full_run_spread_probe.py

Prints, in order (about 40 full runs, 10-20 minutes on one core):

1. Jitter far below the sensor's resolution (range sd 1 mm against its 1 cm quantum, bearing sd
   0.01 deg against the detector's 0.25 deg half-beam), 8 seeds, for four configurations: the
   preset as shipped (closure off), closure on, closure on with the pass offset derived on scans
   1-2000 (0.0546, 0.0385 m), and the measurement sigmas x10 (the weight nothing derives).
2. A systematic bearing scale (every bearing times 1 + e) of e = +-0.1% and +-0.2%: 0.09 and
   0.17 deg at the field of view's edge, under the filter's own bearing sigma.

Diagnosis only: nothing here sets a default, and nothing is chosen on these figures.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from arm_side_probes import scaled  # docs/, beside this script
from threadpoolctl import threadpool_limits

from experiments.eval.gps import score_sequence
from experiments.eval.vouched import vouched_for_sequence
from experiments.io.victoria_park import load_victoria_park
from experiments.paper.victoria_park.real_run import run_config
from slam import run_slam

SEEDS = range(8)
RANGE_SD_M, BEARING_SD_RAD = 0.001, np.radians(0.01)
PASS_OFFSET_M = (0.0546, 0.0385)  # derived on scans 1-2000 (victoria-park-pass-offset)
SCALES = (0.001, -0.001, 0.002, -0.002)


def configurations(cfg) -> dict:
    on = cfg.with_(**{"closure.enabled": True})
    return {
        "preset (closure off)": cfg,
        "closure on": on,
        "closure on, pass offset": on.with_(**{"measurement.pass_offset_sd_m": PASS_OFFSET_M}),
        "sigmas x10 (closure off)": scaled(cfg, 10.0),
    }


def vouched_rmse(seq, cfg, vouched) -> float:
    log = run_slam(seq, cfg)
    return score_sequence(seq, log.scan_t, log.pose, log.antenna_pose, vouched).vouched_rmse


def jittered(seq, seed: int):
    rng = np.random.default_rng(seed)
    n = len(seq.det_range)
    return dataclasses.replace(
        seq,
        det_range=seq.det_range + rng.normal(0.0, RANGE_SD_M, n),
        det_bearing=seq.det_bearing + rng.normal(0.0, BEARING_SD_RAD, n),
    )


def main() -> None:
    threadpool_limits(1)
    seq = load_victoria_park(full=True)
    cfg = run_config("detections", "ihgr")
    vouched = vouched_for_sequence(seq, cfg)
    for name, c in configurations(cfg).items():
        r = np.array([vouched_rmse(jittered(seq, s), c, vouched) for s in SEEDS])
        print(
            f"{name}: unjittered {vouched_rmse(seq, c, vouched):.3f} m; jittered median "
            f"{np.median(r):.3f} m, range {r.min():.3f}-{r.max():.3f} m ({len(r)} seeds)",
            flush=True,
        )
    for e in SCALES:
        s = dataclasses.replace(seq, det_bearing=seq.det_bearing * (1.0 + e))
        print(f"bearing scale {e:+.1%}: {vouched_rmse(s, cfg, vouched):.3f} m", flush=True)


if __name__ == "__main__":
    main()
