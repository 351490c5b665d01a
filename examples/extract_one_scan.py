"""Extract the features of one laser scan: a simulated scan of the bundled pillar court (the
paper's first experiment), fitted with the paper's modified Gauss-Newton (`paper`) and the
geometric fit (`geometric`). The simulator says which object each beam hit, so each circle is
printed with the object behind its beams and, for a pillar, its centre and radius errors.

    python examples/extract_one_scan.py [OUT_DIR]

Writes features.json (both methods' features, laser frame) into OUT_DIR (default: a temp dir).
"""

import json
import sys
import tempfile
from pathlib import Path

import numpy as np

from experiments.io.writers import features_to_dict
from experiments.sim import load_scene, sensor_preset, simulate_scan
from features import extract_features
from slam import se2

out = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(tempfile.mkdtemp(prefix="trunkslam_"))
out.mkdir(parents=True, exist_ok=True)

scene = load_scene("pillar_court")
pose = scene.scan_positions[3]  # position 4, 5-10 m from the east pillars d-g
sensor = sensor_preset("pls200", back_to_back=True)  # two PLS200s: 360 deg at 0.5 deg
ranges_m, labels = simulate_scan(scene, pose, sensor, np.random.default_rng(0))
scan = sensor.scan(ranges_m)
print(f"scan from {pose.tolist()}: {scan.n_beams} beams, {np.isfinite(ranges_m).sum()} returns")

# the true circles (x, y, radius) with their centres in the laser frame (here the vehicle's)
truth = scene.truth_landmarks
truth_xy = se2.transform_points(se2.inverse(pose), truth[:, :2])

result = {}
for method in ("paper", "geometric"):
    f = extract_features(scan, method=method, sigma_r_m=sensor.effective_sigma_m)
    result[method] = features_to_dict(f, 0)
    print(f"{method}: {f.n_circles} circles, {len(f.lines)} lines, {len(f.edges)} edges")
    for c in f.circles:
        hit = labels[c.beam_indices]
        k = int(np.bincount(hit[hit >= 0]).argmax())  # the object most of its beams hit
        line = f"  {method:9s} {scene.label_name(k):7s} range {c.range_m:5.2f} m"
        if k < len(truth):  # labels 0..L-1 are the scene's circles
            err = np.hypot(*(c.center_xy - truth_xy[k]))
            sigma = np.sqrt(np.linalg.eigvalsh(c.cov[:2, :2]).max())
            line += f"  centre error {err:.4f} m (sigma {sigma:.4f})"
            line += f"  radius {c.radius_m:.3f} m (true {truth[k, 2]:.3f})"
        else:
            line += f"  not a circle: a {scene.label_kind(k)} (radius {c.radius_m:.2f} m)"
        print(line)
(out / "features.json").write_text(json.dumps(result, indent=1))
print(f"-> {out / 'features.json'}")
