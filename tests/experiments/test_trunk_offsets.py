"""The trunks' view-dependent centre offset (experiments/eval/trunk_offsets.py): hand-built
passes whose bias is known, and the figure behind `closure.tree_sd_m` on Victoria Park."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from experiments.eval.trunk_offsets import view_offset
from slam.config import ClosureConfig

LASER = np.array([0.5, 0.2, 0.01])


def _drive_past(bias: np.ndarray, noise_m: float, seed: int = 0) -> SimpleNamespace:
    """A log of a vehicle driving along y = 0 at 5 m/s, 10 scans/s, past one tree every 20 m
    at y = 8 m; tree j's measured centre is moved along the line of sight by bias[j], and each
    range and cross-range gets white noise of noise_m."""
    rng = np.random.default_rng(seed)
    trees = np.stack([20.0 * np.arange(bias.size) + 30.0, np.full(bias.size, 8.0)], axis=1)
    t = np.arange(0.0, (trees[-1, 0] + 40.0) / 5.0, 0.1)
    pose = np.stack([5.0 * t, np.zeros_like(t), np.full_like(t, 0.02)], axis=1)
    c, s = math.cos(0.02), math.sin(0.02)
    sensor = pose[:, :2] + [c * LASER[0] - s * LASER[1], s * LASER[0] + c * LASER[1]]
    scans, ids, zs = [], [], []
    for k in range(t.size):
        d = trees - sensor[k]
        r = np.hypot(d[:, 0], d[:, 1])
        for j in np.flatnonzero(r < 25.0):
            rng_m = r[j] + bias[j] + noise_m * rng.standard_normal()
            bearing = math.atan2(d[j, 1], d[j, 0]) + noise_m / r[j] * rng.standard_normal()
            scans.append(k)
            ids.append(j)
            zs.append([rng_m, bearing - 0.02 - LASER[2]])
    return SimpleNamespace(
        n_scans=t.size,
        scan_t=t,
        pose=pose,
        laser_pose=LASER,
        obs_scan=np.array(scans),
        obs_landmark=np.array(ids),
        obs_z=np.array(zs),
    )


def test_the_bias_of_each_tree_is_recovered_and_the_white_noise_left_out():
    bias = np.random.default_rng(1).normal(0.0, 0.1, 300)
    got = view_offset(_drive_past(bias, noise_m=0.03))
    assert got.passes == 300
    assert got.bias_rms_m == pytest.approx(np.sqrt(np.mean(bias**2)), rel=0.05)
    assert got.sd_per_axis_m == pytest.approx(np.sqrt(np.mean(bias**2) / 2.0), rel=0.08)
    clean = view_offset(_drive_past(np.zeros(300), noise_m=0.03))
    # the noise alone scatters b by what its least-squares variance says, and is taken out
    assert clean.bias_rms_m**2 == pytest.approx(clean.noise_var_m2, rel=0.2)
    assert clean.sd_per_axis_m < 0.3 * clean.bias_rms_m


def test_only_the_first_scans_and_qualifying_passes_count():
    lg = _drive_past(np.full(10, 0.2), noise_m=0.0)
    half = view_offset(lg, n_scans=lg.n_scans // 2)
    assert 0 < half.passes < 10
    assert half.bias_mean_m == pytest.approx(0.2, abs=1e-9)
    with pytest.raises(ValueError, match="no pass"):
        view_offset(lg, min_turn_deg=179.0)


@pytest.mark.data
@pytest.mark.slow
def test_the_closure_default_is_the_offset_victoria_park_scans_1_to_2000_show(vp_dir):
    """`closure.tree_sd_m`'s default is this procedure's figure on the calibration scans of
    Victoria Park (the preset's run, published detections), rounded to a centimetre."""
    from experiments.io.victoria_park import load_victoria_park
    from experiments.paper.victoria_park import real_run as vp
    from slam.loop import run_slam

    seq = vp.head(load_victoria_park(vp_dir, full=True), 2000)
    got = view_offset(run_slam(seq, vp.run_config("detections", "ihgr")))
    assert got.passes > 200
    assert round(got.sd_per_axis_m, 2) == ClosureConfig().tree_sd_m
