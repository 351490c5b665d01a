"""Probe behind the lab notebook's entry "The published detections' range error from the
trunks' traces": the range bias (`measurement.range_bias.bailey`, the published detections'
method) derived on scans 1-2000 by the calibration's step (`derive_range_bias`, the trace fit's
fixed point of `experiments.eval.trace_bias`; no GPS), then the runs it was judged by, each
once: scans 1-2000 and the full run, closure off and on, without and with it (VP preset,
published detections, IHGR).

    TRUNKSLAM_DATA=../shared/datasets PYTHONPATH=. .venv/bin/python docs/range_bias_probe.py

Prints one line per run of the fixed point (the bias it ran with, the fit's four terms), the
derived bias, then one line per judged run: its RMSE on the vouched GPS fixes, under the RFS
rule (fixes within 25 ms of a scan), and its landmarks. About five minutes on one core.
"""

from __future__ import annotations

from threadpoolctl import threadpool_limits

from experiments.eval.gps import score_sequence
from experiments.eval.vouched import vouched_for_sequence
from experiments.io.victoria_park import load_victoria_park
from experiments.paper.victoria_park.calibration import (
    RANGE_BIAS_METHOD,
    RANGE_BIAS_RUNS,
    derive_range_bias,
)
from experiments.paper.victoria_park.real_run import run_config
from slam import SlamConfig, run_slam


def with_bias(cfg: SlamConfig, bias) -> SlamConfig:
    return cfg.with_(**{"measurement.range_bias": {RANGE_BIAS_METHOD: tuple(bias)}})


def derive(cfg: SlamConfig) -> tuple[float, float]:
    bias, history = derive_range_bias(load_victoria_park(n_scans=2000), cfg, RANGE_BIAS_RUNS)
    for (a, b), f in history:
        print(
            f"bias a {a:+.4f} m, b {b:+.6f} per m: fit b0 {100 * f.range_offset_m:+.2f} cm (se "
            f"{100 * f.se[0]:.2f}), p0 {100 * f.across_offset_m:+.2f} cm, bearing scale "
            f"{100 * f.bearing_scale:+.3f}%, range scale {100 * f.range_scale:+.3f}% (se "
            f"{100 * f.se[3]:.3f}), {f.passes} passes"
        )
    print(f"derived: a {bias[0]:+.4f} m, b {bias[1]:+.6f} per m")
    return bias


def judge(cfg: SlamConfig, bias) -> None:
    for name, full, closure in (
        ("scans 1-2000", False, False),
        ("full run", True, False),
        ("full run, closure on", True, True),
    ):
        seq = load_victoria_park(full=full)
        c = cfg.with_(**{"closure.enabled": closure})
        vouched = vouched_for_sequence(seq, c)
        for label, b in (("without", (0.0, 0.0)), ("with", bias)):
            log = run_slam(seq, with_bias(c, b))
            s = score_sequence(seq, log.scan_t, log.pose, log.antenna_pose, vouched=vouched)
            print(
                f"{name}, {label} the range bias: vouched {s.vouched_rmse:.3f} m, RFS rule "
                f"{s.rfs_rmse:.3f} m, {len(log.landmark_xy)} landmarks"
            )


def main() -> None:
    threadpool_limits(1)
    cfg = run_config("detections", "ihgr")
    judge(cfg, derive(cfg))


if __name__ == "__main__":
    main()
