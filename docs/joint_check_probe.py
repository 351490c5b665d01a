"""Probe behind the notebook's entry on the joint check of a scan's pairings (issue 39,
`[association] joint_check`): scans 1-2000 of Victoria Park with the `victoria_park_ute`
preset as `trunkslam reproduce victoria-park` runs them (published detections, IHGR), with
the check off (the preset) and on.

    TRUNKSLAM_DATA=../shared/datasets PYTHONPATH=. .venv/bin/python docs/joint_check_probe.py

Printed for each: RMSE on the odometry-vouched GPS fixes and under the RFS rule
(`experiments.eval.gps.score_sequence`), landmarks, the batch NIS per degree of freedom over
the scans with an update (sum of NIS / sum of dof), the share of those scans whose NIS is
inside its 95% bounds (`real_run.nis_inside`), and the pairings the check dropped (in how many
scans). The full run and the protocol's draws are measured by `trunkslam slam` and
docs/rfs_draw_probe.py --joint-check.
"""

from __future__ import annotations

import numpy as np
from threadpoolctl import threadpool_limits

from experiments.eval.gps import score_sequence
from experiments.eval.vouched import vouched_for_sequence
from experiments.io.victoria_park import load_victoria_park
from experiments.paper.victoria_park.real_run import nis_inside, run_config
from slam import run_slam


def main() -> None:
    seq = load_victoria_park()
    cfg = run_config("detections", "ihgr")
    vouched = vouched_for_sequence(seq, cfg)
    with threadpool_limits(1):
        for on in (False, True):
            lg = run_slam(seq, cfg.with_(**{"association.joint_check": on}))
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


if __name__ == "__main__":
    main()
