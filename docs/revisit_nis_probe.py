"""Probe behind the lab notebook's entry "The revisit NIS: the filter is not surprised when it
comes back" (issue 39): the innovation of a landmark's first sighting after a gap, normalised
by the covariance the filter predicted for it, on Victoria Park (VP preset, published
detections, IHGR, closure off).

    TRUNKSLAM_DATA=../shared/datasets PYTHONPATH=. .venv/bin/python docs/revisit_nis_probe.py

A white model of an error that is correlated over a pass or a stretch keeps the scan-to-scan
NIS near its degrees of freedom but makes the filter over-confident over long horizons: the
sightings of a landmark seen again after a gap (another pass, the way back) would then have a
NIS far above chi-square(2). Prints, for scans 1-2000 with every measurement sigma times k = 1,
3 and 10, and for the full run (all of it, before 1000 s, and the north-west arm's way back,
1240-1400 s), each gap bin's sightings: how many, their NIS median over chi-square(2)'s median,
their mean NIS per dof, and the share above chi-square(2)'s 95% quantile. Only sightings the
association accepted are counted (the gate at 0.999 censors the largest), and a landmark's
first sighting in the map has no gap. About two minutes on one core.
"""

from __future__ import annotations

import numpy as np
from scipy import stats
from threadpoolctl import threadpool_limits

from experiments.eval.gps import score_sequence
from experiments.eval.vouched import vouched_for_sequence
from experiments.io.victoria_park import load_victoria_park
from experiments.paper.victoria_park.calibration import scale_measurement_noise
from experiments.paper.victoria_park.real_run import run_config
from slam import run_slam

GAPS_S = (0.0, 2.0, 30.0, 120.0, np.inf)  # 2 s: measurement.pass_gap_s, a pass's gap
CHI2_MEDIAN = stats.chi2.median(2)
CHI2_95 = stats.chi2.ppf(0.95, 2)


def sightings_after_gaps(log):
    """(time, gap since the landmark's last sighting, NIS) of every sighting used in an update;
    the gap is NaN at a landmark's first."""
    t = log.scan_t[log.obs_scan]
    order = np.lexsort((t, log.obs_landmark))
    landmark, t = log.obs_landmark[order], t[order]
    nu, S = log.obs_innov[order], log.obs_innov_cov[order]
    nis = np.einsum("ni,ni->n", nu, np.linalg.solve(S, nu[:, :, None])[:, :, 0])
    gap = np.r_[np.nan, np.diff(t)]
    gap[np.r_[True, landmark[1:] != landmark[:-1]]] = np.nan
    return t, gap, nis


def print_bins(label: str, log, t_lo: float = -np.inf, t_hi: float = np.inf) -> None:
    t, gap, nis = sightings_after_gaps(log)
    if label:
        print(label)
    for lo, hi in zip(GAPS_S[:-1], GAPS_S[1:]):
        x = nis[(gap > lo) & (gap <= hi) & (t >= t_lo) & (t < t_hi)]
        if x.size == 0:
            print(f"  gap ({lo:g}, {hi:g}] s: none")
            continue
        print(
            f"  gap ({lo:g}, {hi:g}] s: {x.size} sightings, median / chi2 median "
            f"{np.median(x) / CHI2_MEDIAN:.2f}, mean per dof {x.mean() / 2:.2f}, above chi2 95% "
            f"{np.mean(x > CHI2_95):.3f}"
        )


def run(seq, cfg, label: str):
    log = run_slam(seq, cfg)
    s = score_sequence(
        seq, log.scan_t, log.pose, log.antenna_pose, vouched=vouched_for_sequence(seq, cfg)
    )
    nis = np.nansum(log.scan_nis) / log.scan_nis_dof.sum()
    print(f"{label}: vouched {s.vouched_rmse:.3f} m, scans' NIS per dof {nis:.3f}")
    return log


def main() -> None:
    threadpool_limits(1)
    cfg = run_config("detections", "ihgr")
    first = load_victoria_park(n_scans=2000)
    for k in (1.0, 3.0, 10.0):
        c = cfg if k == 1.0 else scale_measurement_noise(cfg, k)
        print_bins("", run(first, c, f"scans 1-2000, sigmas x{k:g}"))
    log = run(load_victoria_park(full=True), cfg, "full run")
    print_bins("  all of it", log)
    print_bins("  before 1000 s", log, t_hi=1000.0)
    print_bins("  the arm's way back, 1240-1400 s", log, 1240.0, 1400.0)


if __name__ == "__main__":
    main()
