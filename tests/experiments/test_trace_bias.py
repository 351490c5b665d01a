"""experiments.eval.trace_bias: the shared terms recovered from synthetic passes with known
errors, the range bias that removes them, and the fixed point."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from experiments.errors import DataError
from experiments.eval.trace_bias import (
    TraceFit,
    compose_range_bias,
    derive_range_bias,
    trace_fit,
    trace_passes,
)
from slam import se2

LASER = np.array([3.78, 0.5, 0.0])
TREES = np.array([(x, y) for x in np.arange(20.0, 200.0, 15.0) for y in (-9.0, 7.0)])


def drive(b0=0.0, p0=0.0, e=0.0, g=0.0, bias=(0.0, 0.0)):
    """A straight drive at 3 m/s past two rows of trees, every sighting under 40 m and within
    +-85 deg made with the given errors in the fit's terms (the apparent range r exceeds the
    true one by b0 + g r, the apparent bearing by e beta + p0 / r) and then corrected by `bias`
    as `measurement.range_bias` would."""
    t = np.arange(0.0, 70.0, 0.2)
    pose = np.c_[3.0 * t, np.zeros_like(t), np.zeros_like(t)]
    scan, landmark, z = [], [], []
    for k, p in enumerate(pose):
        r, beta = se2.observe(p, TREES, LASER)[0].T
        seen = (r < 40.0) & (np.abs(beta) < math.radians(85.0))
        r_obs = (r[seen] + b0) / (1.0 - g)
        beta_obs = (beta[seen] + p0 / r[seen]) / (1.0 - e)
        r_obs = r_obs - (bias[0] + bias[1] * r_obs)
        scan += [k] * seen.sum()
        landmark += list(np.flatnonzero(seen))
        z += list(zip(r_obs, beta_obs, strict=True))
    return SimpleNamespace(
        scan_t=t, pose=pose, laser_pose=LASER, obs_scan=np.array(scan),
        obs_landmark=np.array(landmark), obs_z=np.array(z),
    )  # fmt: skip


def test_the_fit_recovers_known_errors():
    fit = trace_fit(drive(b0=0.07, p0=0.012, e=-0.0009, g=-0.0023))
    assert fit.passes == len(TREES) and fit.sightings > 1000
    assert fit.range_offset_m == pytest.approx(0.07, abs=1e-4)  # the bearing terms, linearised
    assert fit.across_offset_m == pytest.approx(0.012, abs=2e-4)
    assert fit.bearing_scale == pytest.approx(-0.0009, abs=1e-5)
    assert fit.range_scale == pytest.approx(-0.0023, abs=1e-5)
    assert all(0 < s < 1e-3 for s in fit.se)  # noise-free: only the linearisation is left


def test_white_noise_gives_zero_terms_within_their_errors():
    log = drive()
    rng = np.random.default_rng(3)
    log.obs_z = log.obs_z + rng.normal(0, [0.03, 0.003], log.obs_z.shape)
    fit = trace_fit(log)
    terms = (fit.range_offset_m, fit.across_offset_m, fit.bearing_scale, fit.range_scale)
    assert all(abs(v) < 4 * s for v, s in zip(terms, fit.se, strict=True))
    assert fit.se[0] > 1e-3  # the noise shows in the errors


def test_the_composed_bias_removes_the_error():
    fit = trace_fit(drive(b0=0.07, g=-0.0023, bias=(0.02, 0.001)))
    a, b = compose_range_bias((0.02, 0.001), fit)
    again = trace_fit(drive(b0=0.07, g=-0.0023, bias=(a, b)))
    assert abs(again.range_offset_m) < 1e-9 and abs(again.range_scale) < 1e-10
    assert (a, b) == pytest.approx((0.07, -0.0023), abs=1e-6)


def test_the_fixed_point_settles_and_says_when_it_does_not():
    runs = []

    def run(bias):
        runs.append(bias)
        return drive(b0=0.07, g=-0.0023, bias=bias)

    bias, history = derive_range_bias(run)
    assert len(history) == 2 and runs[0] == (0.0, 0.0)  # exact poses: one correction settles it
    assert bias == pytest.approx((0.07, -0.0023), abs=1e-6)
    with pytest.raises(
        DataError, match=r"did not settle in 1 runs \(the last ran with a \+0\.0000"
    ):
        derive_range_bias(run, max_iterations=1)
    with pytest.raises(ValueError, match="max_iterations must be an int >= 1"):
        derive_range_bias(run, max_iterations=0)


def test_a_pose_or_measurement_not_finite_is_named():
    for field, row in (("obs_z", 5), ("pose", 3)):
        log = drive()
        getattr(log, field)[row, 0] = np.nan
        with pytest.raises(DataError, match="not finite"):
            trace_fit(log)


def test_passes_that_cannot_tell_the_terms_apart_are_refused():
    log = drive()
    log.obs_z[:, 0] = 10.0  # every range alike: the range offset and scale are one column
    with pytest.raises(DataError, match="cannot tell the four terms apart"):
        trace_fit(log)


def test_passes_need_a_turn_and_a_window():
    log = drive()
    assert len(trace_passes(log)) == len(TREES)
    assert trace_passes(log, min_turn_rad=math.radians(179.0)) == []
    inside = trace_passes(log, 0.0, 30.0)  # only passes over by 30 s
    assert 0 < len(inside) < len(TREES)
    assert all(log.scan_t[log.obs_scan[p[-1]]] < 30.0 for p in inside)
    with pytest.raises(DataError, match="at least 2 passes"):
        trace_fit(log, 0.0, 1.0)


def test_fit_is_a_frozen_record():
    fit = TraceFit(0.0, 0.0, 0.0, 0.0, (1.0, 1.0, 1.0, 1.0), 2, 12)
    with pytest.raises(AttributeError):
        fit.range_offset_m = 1.0  # type: ignore[misc]
