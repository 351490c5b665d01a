"""The steering calibration from dead reckoning against GPS stretches (vp_steering.py)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from experiments.errors import DataError
from experiments.paper.victoria_park.steering import dead_reckoning_mse, fit_steering, stretches
from slam import AckermannModel, Odometry, Sequence, SteeringCalibration, se2
from slam.vehicle import integrate

CAR = {"model": "ackermann", "wheelbase_m": 2.83, "encoder_offset_m": 0.76}
ANTENNA = np.array([3.78, 0.5, 0.0])
TRUE = SteeringCalibration(offset_rad=0.005, gain=1.02, cubic_per_rad2=0.2)


def ute_drive(seconds: float = 480.0, gps_sigma: float = 0.05, seed: int = 0) -> Sequence:
    """A ute weaving at 3 m/s (readings r up to 0.45 rad); the truth turns by TRUE's angle;
    GPS at 5 Hz with `gps_sigma` noise and one 40 m jump; a scan every second."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, seconds, 0.05)
    r = 0.45 * np.sin(2 * np.pi * t / 37.0) * np.sin(2 * np.pi * t / 11.0)
    v = np.full(t.size, 3.0)
    truth = Odometry(t, v, TRUE.apply(r))
    car = AckermannModel.from_vehicle(CAR)
    gps_t = t[::4]
    pose, t0, xy = np.zeros(3), 0.0, []
    for tk in gps_t:
        pose = integrate(car, pose, truth, t0, float(tk))[0]
        t0 = float(tk)
        xy.append(se2.compose(pose, ANTENNA)[:2])
    xy = np.array(xy) + gps_sigma * rng.standard_normal((gps_t.size, 2))
    xy[700] += 40.0  # a jump: flagged and left out
    scan_t = np.arange(0.0, seconds - 1.0, 1.0)
    return Sequence(
        scan_t=scan_t,
        det_scan=np.zeros(0, np.int64),
        det_range=np.zeros(0),
        det_bearing=np.zeros(0),
        det_radius=np.zeros(0),
        det_method="bailey",
        laser_pose=np.array([3.78, 0.5, 0.0]),
        scan_angle_min=-math.pi / 2,
        scan_angle_increment=math.pi / 360,
        scan_n_beams=361,
        scan_max_range=80.0,
        odo_t=t,
        odo_speed=v,
        odo_steer=r,
        vehicle=CAR,
        gps_t=gps_t,
        gps_xy=xy,
        gps_pose=ANTENNA,
    )


@pytest.mark.slow
def test_fit_recovers_a_known_miscalibration_and_holds_out_the_rest():
    """Readings whose true angle is 0.005 + 1.02 r + 0.2 r^3: the fit on the first 240 scans
    (4 stretches of 60 s) finds the three parameters, and the dead-reckoning error falls to the
    GPS noise on the stretches it never saw."""
    seq = ute_drive()
    got = fit_steering(seq, fit_scans=240, evaluations=300)
    assert got.fit_stretches == 4 and got.held_out_stretches == 3
    assert got.steering.offset_rad == pytest.approx(0.005, abs=5e-4)
    assert got.steering.gain == pytest.approx(1.02, abs=0.01)
    assert got.steering.cubic_per_rad2 == pytest.approx(0.2, abs=0.05)
    assert got.fit_mse_before > 1.0 and got.held_out_mse_before > 1.0
    assert got.held_out_mse_after < 3 * 2 * 0.05**2  # E|d|^2 = 2 sigma^2 at the truth
    # the identity on readings that need none leaves nothing to gain
    exact = dead_reckoning_mse(seq, TRUE, stretches(seq, 240.0, 478.0))
    assert exact[1] == 3 and exact[0] < 3 * 2 * 0.05**2


def test_the_jump_is_left_out_and_missing_gps_is_named():
    seq = ute_drive()
    groups = stretches(seq, 0.0, 478.0)
    assert 700 not in np.concatenate(groups) and len(groups) == 7
    no_gps = dataclasses.replace(seq, gps_t=None, gps_xy=None, gps_pose=None)
    with pytest.raises(DataError, match="needs GPS, odometry and a vehicle"):
        fit_steering(no_gps, fit_scans=240)
    with pytest.raises(DataError, match="no stretch of the first 30 scans"):
        fit_steering(seq, fit_scans=30)


@pytest.mark.slow
@pytest.mark.data
def test_on_victoria_park_the_fit_halves_the_held_out_dead_reckoning_error(vp_dir):
    """Fitted on the GPS stretches of scans 1-2000, the calibration brings dead reckoning
    closer to the GPS on the stretches of scans 2001-7249 too (measured 3.60 -> 1.10 m^2)."""
    from experiments.io.victoria_park import load_victoria_park

    got = fit_steering(load_victoria_park(vp_dir, full=True), 2000)
    assert got.fit_stretches == 7 and got.held_out_stretches == 17
    assert got.fit_mse_after < 0.3 * got.fit_mse_before
    assert got.held_out_mse_after < 0.5 * got.held_out_mse_before
    assert 0.0 < got.steering.offset_rad < math.radians(1.0)
    assert got.steering.cubic_per_rad2 > 0.05  # tight turns turn more than tan(r) says
