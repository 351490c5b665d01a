"""The measurement model's known range bias: a filter told of a bias that every tree shares
stays consistent; one that is not told grows over-confident (pose NEES above its bounds)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from experiments.eval.poses import nees, nees_bounds, pose_errors
from features.types import Features
from slam import SlamConfig, interpolate_poses, run_slam, se2
from slam.config import MeasurementConfig, OdometryNoise, StartConfig
from slam.measurement import NoiseModel

from .test_run import LASER, drive_sequence

TREES = np.array(
    [[8.0, 4.0], [12.0, -3.0], [16.0, 5.0], [20.0, -4.0], [6.0, 9.0], [3.0, 12.0], [-2.0, 10.0]]
)
SIGMA_R, SIGMA_B = 0.01, 0.002
NOISE = NoiseModel(SIGMA_R, 0.0, SIGMA_B, 0.0)  # the constant model of the "paper" circles
BIAS_M = -0.03  # injected: every centre 3 cm too close, in every scan (fully correlated)


def _one_run(rng, n_scans=60):
    seq = drive_sequence(1.5, 0.15, n_scans=n_scans)
    on = OdometryNoise()
    seq = dataclasses.replace(
        seq,
        odo_speed=seq.odo_speed + on.speed_sigma_mps * rng.standard_normal(seq.odo_t.size),
        odo_steer=seq.odo_steer + on.steer_sigma_rad * rng.standard_normal(seq.odo_t.size),
    )
    truth = interpolate_poses(seq.scan_t, seq.truth_t, seq.truth_pose)
    feats = []
    for k, p in enumerate(truth):
        lp = se2.compose(p, LASER)
        d = TREES - lp[:2]
        r = np.hypot(d[:, 0], d[:, 1])
        b = se2.wrap_angle(np.arctan2(d[:, 1], d[:, 0]) - lp[2])
        keep = (np.abs(b) < np.pi / 2) & (r < 25)
        r = r[keep] + BIAS_M + SIGMA_R * rng.standard_normal(keep.sum())
        b = b[keep] + SIGMA_B * rng.standard_normal(keep.sum())
        n = r.size
        feats.append(
            dataclasses.replace(
                Features.empty(float(seq.scan_t[k]), "paper"),
                circle_params=np.column_stack([r * np.cos(b), r * np.sin(b), np.full(n, 0.3)]),
                circle_cov=np.zeros((n, 3, 3)),
                circle_beams=np.zeros((n, 2), np.int64),
                circle_rms_m=np.zeros(n),
            )
        )
    return seq, truth, feats


@pytest.fixture(scope="module")
def runs():
    rng = np.random.default_rng(20)
    return [_one_run(g) for g in rng.spawn(12)]


@pytest.mark.slow
@pytest.mark.parametrize("told", [True, False], ids=["bias-known", "bias-unknown"])
def test_known_range_bias_keeps_the_pose_nees_inside_its_bounds(runs, told):
    cfg = SlamConfig(
        measurement=MeasurementConfig(
            noise="constant",
            constant_noise={"paper": NOISE},
            range_bias={"paper": (BIAS_M if told else 0.0, 0.0)},
        ),
        start=StartConfig(initial_pose_sigma=(0.0, 0.0, 0.0)),
    )
    e_runs = []
    for seq, truth, feats in runs:
        lg = run_slam(seq, features=feats, config=cfg)
        assert lg.landmark_xy.shape[0] == TREES.shape[0]
        e = pose_errors(lg.pose, truth)
        e_runs.append(nees(e[1:], lg.pose_cov[1:]))
    avg = np.mean(e_runs, axis=0)[5:]  # the map is built by scan 3
    lo, hi = nees_bounds(len(runs))
    inside = float(np.mean((avg >= lo) & (avg <= hi)))
    if told:
        assert inside >= 0.9, inside
    else:
        assert inside <= 0.5 and float(np.mean(avg > hi)) >= 0.5, inside
