"""Score a run against the sequence's GPS with `experiments.eval.gps`: the antenna point of the
estimated path against every fix in the run's time span (the pose interpolated at the fix's
time), as is and after the best rigid 2D alignment, with the fixes flagged as jumps left out of
the clean figures.

    python examples/score_against_gps.py [OUT_DIR]             # simulate a drive, run SLAM
                                                               # (the cycab preset)
    python examples/score_against_gps.py SEQUENCE.npz RUN_DIR  # a `trunkslam slam` output

e.g. RUN_DIR from `trunkslam slam vp.npz --features detections --config victoria_park_ute
--out RUN_DIR`. Writes gps_score.json into RUN_DIR, or OUT_DIR (default: a temp dir).
"""

import json
import sys
import tempfile
from pathlib import Path

import numpy as np

from experiments.eval.gps import score_sequence
from experiments.io.config_file import load_slam_config
from experiments.io.sequence_file import load_sequence
from experiments.sim import CycabParams, simulate_cycab_run
from slam import run_slam

if len(sys.argv) > 3:
    sys.exit(f"usage: {sys.argv[0]} [OUT_DIR] | SEQUENCE.npz RUN_DIR")
if len(sys.argv) == 3:  # an existing run: its trajectory.csv (t, x, y, theta, covariance)
    seq, out = load_sequence(sys.argv[1]), Path(sys.argv[2])
    table = np.loadtxt(out / "trajectory.csv", delimiter=",", skiprows=1, ndmin=2)
    scan_t, pose = table[:, 0], table[:, 1:4]
    antenna = json.loads((out / "summary.json").read_text())["gps"]["antenna_pose"]
else:  # a simulated tree-park drive with 2 cm DGPS at 10 Hz
    seq = simulate_cycab_run(np.random.default_rng(0), "tree_park", CycabParams(n_scans=240))
    log = run_slam(seq, load_slam_config("cycab"))  # the simulated Cycab's: paper's, IHGR
    scan_t, pose, antenna = log.scan_t, log.pose, log.antenna_pose
    out = Path(sys.argv[1]) if len(sys.argv) == 2 else Path(tempfile.mkdtemp(prefix="trunkslam_"))
    out.mkdir(parents=True, exist_ok=True)

s = score_sequence(seq, scan_t, pose, antenna)
print(f"{s.matched} fixes in the run's time span ({s.unmatched} outside), {s.jumps} jumps")
print(f"all fixes:   RMSE {s.all_rmse:.4f} m, median {s.all_median:.4f} m, p95 {s.all_p95:.4f} m")
print(f"no jumps:    RMSE {s.clean_rmse:.4f} m, median {s.clean_median:.4f} m")
print(f"aligned:     RMSE {s.clean_rmse_aligned:.4f} m (rotated {s.rotation_deg:.3f} deg)")
(out / "gps_score.json").write_text(json.dumps(s.to_dict(), indent=1))
print(f"-> {out / 'gps_score.json'}")
