"""Independent Monte Carlo runs: the true path varies between runs (`MONTE_CARLO_PATH`).

An extractor's error is largely fixed by the geometry (which beams hit a trunk). Runs that all
drive one path therefore repeat the same errors, and the NEES averaged over them is not the
average of independent runs. Here such an error is injected with known size: every trunk is
measured at the centre of the cell of a range-bearing grid its true centre falls in (0.5 deg,
the beam spacing, by 5 cm), errors uniform over a cell (sd 2.5 mrad and 14 mm, which the
filter is told); only the odometry noise is drawn anew in every run.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from experiments.errors import ConfigError
from experiments.eval.poses import nees, nees_bounds, pose_errors
from experiments.sim.scene import load_scene
from experiments.sim.trajectory import (
    MONTE_CARLO_PATH,
    CycabParams,
    drive,
    route_polyline,
    simulate_cycab_run,
)
from features.types import Features
from slam import SlamConfig, interpolate_poses, run_slam, se2
from slam.config import MeasurementConfig

CELL = math.pi / 360  # the beam spacing
SIGMA_B = CELL / math.sqrt(12)  # sd of an error uniform over one cell
RANGE_CELL = 0.05
SIGMA_R = RANGE_CELL / math.sqrt(12)
N_RUNS, N_SCANS = 32, 120


def _quantised_features(seq) -> list:
    """Each trunk in front of the laser within 25 m, at the centre of the range-bearing cell of
    its true centre: an error fixed by the geometry."""
    truth = interpolate_poses(seq.scan_t, seq.truth_t, seq.truth_pose)
    lm = seq.truth_landmarks
    feats = []
    for k, p in enumerate(truth):
        lp = se2.compose(p, seq.laser_pose)
        d = lm[:, :2] - lp[:2]
        r = np.hypot(d[:, 0], d[:, 1])
        b = np.asarray(se2.wrap_angle(np.arctan2(d[:, 1], d[:, 0]) - lp[2]))
        keep = (np.abs(b) < math.radians(85)) & (r < 25)
        r = (np.floor(r[keep] / RANGE_CELL) + 0.5) * RANGE_CELL
        b = (np.floor(b[keep] / CELL) + 0.5) * CELL
        n = r.size
        feats.append(
            dataclasses.replace(
                Features.empty(float(seq.scan_t[k]), "bailey"),
                circle_params=np.column_stack([r * np.cos(b), r * np.sin(b), lm[keep, 2]]),
                circle_cov=np.zeros((n, 3, 3)),
                circle_beams=np.zeros((n, 2), np.int64),
                circle_rms_m=np.zeros(n),
            )
        )
    return feats


def _nees_in_bounds(cycab: CycabParams) -> tuple[float, float]:
    """(share of scans inside, share above) the 95% bounds of the run-averaged pose NEES."""
    cfg = SlamConfig(
        measurement=MeasurementConfig(
            noise="constant",
            constant_noise={"bailey": (SIGMA_R, 0.0, SIGMA_B, 0.0)},
            range_bias={"bailey": (0.0, 0.0)},
        )
    )
    out = []
    for g in np.random.default_rng(7).spawn(N_RUNS):
        seq = simulate_cycab_run(g, "tree_park", cycab)
        truth = interpolate_poses(seq.scan_t, seq.truth_t, seq.truth_pose)
        lg = run_slam(seq, features=_quantised_features(seq), config=cfg)
        out.append(nees(pose_errors(lg.pose, truth)[1:], lg.pose_cov[1:]))
    avg = np.mean(out, axis=0)
    lo, hi = nees_bounds(N_RUNS)
    return float(np.mean((avg >= lo) & (avg <= hi))), float(np.mean(avg > hi))


@pytest.fixture(scope="module")
def figures() -> dict:
    return {
        "one path": _nees_in_bounds(CycabParams(n_scans=N_SCANS)),
        "varied paths": _nees_in_bounds(CycabParams(n_scans=N_SCANS, **MONTE_CARLO_PATH)),
    }


@pytest.mark.slow
def test_runs_along_one_path_share_the_geometry_fixed_error(figures):
    inside, above = figures["one path"]
    assert inside <= 0.6, figures


@pytest.mark.slow
def test_varied_paths_make_the_runs_independent(figures):
    inside, above = figures["varied paths"]
    assert inside >= 0.9 and above <= 0.02, figures


def _signed_offsets(route: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Signed distance (left positive) of each point from the nearest vertex of a closed route."""
    i = np.argmin(
        np.hypot(xy[:, None, 0] - route[None, :, 0], xy[:, None, 1] - route[None, :, 1]), 1
    )
    t = np.roll(route, -1, axis=0)[i] - np.roll(route, 1, axis=0)[i]
    t /= np.hypot(t[:, 0], t[:, 1])[:, None]
    d = xy - route[i]
    return t[:, 0] * d[:, 1] - t[:, 1] * d[:, 0]


def test_the_drive_follows_the_shifted_route_from_the_moved_start():
    sc, p = load_scene("tree_park"), CycabParams()
    route = route_polyline(sc.scan_positions)
    d = drive(sc, p, 600, offset_m=0.3, start_along_m=1.0)
    # the start: about 1 m along the first leg, 0.3 m to its left (the shifted route's normal
    # at the corner it starts from is the corner's bisector), heading along it
    a, b = route[0], route[10]
    u = (b - a) / np.hypot(*(b - a))
    want = a + 1.0 * u + 0.3 * np.array([-u[1], u[0]])
    assert d.pose[0, :2] == pytest.approx(want, abs=0.05)
    assert d.pose[0, 2] == pytest.approx(math.atan2(u[1], u[0]), abs=0.01)
    # pure pursuit cuts the corners alike with and without the shift
    off0 = np.median(_signed_offsets(route, drive(sc, p, 600).pose[:, :2]))
    assert np.median(_signed_offsets(route, d.pose[:, :2])) - off0 == pytest.approx(0.3, abs=0.03)


def test_without_variation_every_run_drives_the_same_path_from_the_first_waypoint():
    sc = load_scene("tree_park")
    p = CycabParams(n_scans=30)
    a, b = (simulate_cycab_run(g, sc, p) for g in np.random.default_rng(1).spawn(2))
    assert np.array_equal(a.truth_pose, b.truth_pose)
    assert a.truth_pose[0] == pytest.approx(sc.scan_positions[0], abs=0)
    assert not np.array_equal(a.odo_steer, b.odo_steer)  # the noise is drawn anew


def test_path_variation_draws_its_own_stream_and_leaves_the_noise_as_it_was():
    p0 = CycabParams(n_scans=30)
    p1 = CycabParams(n_scans=30, **MONTE_CARLO_PATH)
    a = simulate_cycab_run(np.random.default_rng(3), "tree_park", p0)
    b = simulate_cycab_run(np.random.default_rng(3), "tree_park", p1)
    c = simulate_cycab_run(np.random.default_rng(4), "tree_park", p1)
    # the speed does not depend on the path (encoder at the axle centre): same readings, same noise
    assert np.array_equal(a.odo_speed, b.odo_speed)
    assert not np.allclose(a.truth_pose, b.truth_pose)
    assert not np.allclose(b.truth_pose[0], c.truth_pose[0])


@pytest.mark.parametrize("name", ["route_offset_sigma_m", "start_along_m"])
def test_negative_path_variation_is_refused_by_name(name):
    with pytest.raises(ConfigError, match=name):
        CycabParams(**{name: -0.1})


def test_experiment_2s_filter_is_told_the_simulated_odometry_noise_and_no_slip():
    from experiments.paper.slam import CYCAB_SLAM, Exp2Config

    sim, model = Exp2Config().cycab, Exp2Config().slam.vehicle.odometry_noise
    assert Exp2Config().slam == CYCAB_SLAM
    assert (model.speed_sigma_mps, model.steer_sigma_rad) == (
        sim.speed_sigma_mps,
        sim.steer_sigma_rad,
    )
    assert model.floor_xy_m_per_sqrt_s == model.floor_theta_rad_per_sqrt_s == 0.0
    assert model.speed_sigma_per_speed == model.steer_sigma_per_lateral_mps2 == 0.0
    varied = (MONTE_CARLO_PATH["route_offset_sigma_m"], MONTE_CARLO_PATH["start_along_m"])
    assert (sim.route_offset_sigma_m, sim.start_along_m) == varied
