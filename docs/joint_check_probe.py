"""Probe behind the notebook's entry on the joint check of a scan's pairings (issue 39,
`[association] joint_check`): scans 1-2000 of Victoria Park with the `victoria_park_ute`
preset as `trunkslam reproduce victoria-park` runs them (published detections, IHGR), with
the check off (the preset) and on.

    TRUNKSLAM_DATA=../shared/datasets PYTHONPATH=. .venv/bin/python docs/joint_check_probe.py \
        [--full]

Printed for each: RMSE on the odometry-vouched GPS fixes and under the RFS rule
(`experiments.eval.gps.score_sequence`), landmarks, the batch NIS per degree of freedom over
the scans with an update (sum of NIS / sum of dof), the share of those scans whose NIS is
inside its 95% bounds (`real_run.nis_inside`), and the pairings the check dropped (in how many
scans). With --full the same for the full run (closure off, the preset's), and where the run
with the check departs from the preset's (its rear-axle path 0.1 m and 1 m away), with the
pairings dropped before each departure. The protocol's draws: docs/rfs_draw_probe.py
--joint-check.
"""

from __future__ import annotations

import sys

import numpy as np
from threadpoolctl import threadpool_limits

from experiments.eval.gps import score_sequence
from experiments.eval.vouched import vouched_for_sequence
from experiments.io.victoria_park import load_victoria_park
from experiments.paper.victoria_park.real_run import nis_inside, run_config
from slam import run_slam


def departures(on, off) -> None:
    """Where the run with the check departs from the preset's, and what it dropped before."""
    gap = np.hypot(*(on.pose[:, :2] - off.pose[:, :2]).T)
    t0, scans = on.scan_t[0], np.array([r[0] for r in on.joint_dropped], np.int64)
    for m in (0.1, 1.0):
        if not (gap > m).any():
            print(f"  never {m} m from the preset's path")
            continue
        k = int(np.argmax(gap > m))
        before = scans[scans <= k]
        last = ", ".join(f"{on.scan_t[j] - t0:.1f} s" for j in before[-3:])
        print(
            f"  {m} m from the preset's path at scan {k} ({on.scan_t[k] - t0:.1f} s); pairings "
            f"dropped up to it {before.size} (the last at {last})"
        )


def main() -> None:
    full = "--full" in sys.argv[1:]
    seq = load_victoria_park(full=full)
    cfg = run_config("detections", "ihgr")
    vouched = vouched_for_sequence(seq, cfg)
    logs = []
    with threadpool_limits(1):
        for on in (False, True):
            lg = run_slam(seq, cfg.with_(**{"association.joint_check": on}))
            logs.append(lg)
            sc = score_sequence(seq, lg.scan_t, lg.pose, lg.antenna_pose, vouched)
            ok = lg.scan_nis_dof > 0
            per_dof = float(np.sum(lg.scan_nis[ok]) / np.sum(lg.scan_nis_dof[ok]))
            dropped = lg.joint_dropped or []
            print(
                f"scans 1-{lg.n_scans}, joint check {'on' if on else 'off'}: vouched "
                f"{sc.vouched_rmse:.4f} m, RFS rule {sc.rfs_rmse:.4f} m, landmarks "
                f"{lg.landmark_xy.shape[0]}, NIS per dof {per_dof:.3f}, NIS inside 95% "
                f"{float(np.mean(nis_inside(lg))):.3f}, pairings dropped {len(dropped)} in "
                f"{len({r[0] for r in dropped})} scans",
                flush=True,
            )
    departures(logs[1], logs[0])


if __name__ == "__main__":
    main()
