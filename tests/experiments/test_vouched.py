"""The GPS fixes the odometry vouches for (issue 27's rule): a hand-built GPS track with a hop,
an offset stretch and a lone burst between dropouts keeps exactly the fixes it should."""

from __future__ import annotations

import math

import numpy as np
import pytest

from experiments.eval.vouched import VouchRule, vouched_fixes
from slam import se2


def _drive(t: np.ndarray) -> np.ndarray:
    """(G, 2) a car at 4 m/s along a gentle S-curve."""
    heading = 0.3 * np.sin(t / 15.0)
    dt = np.diff(t, prepend=t[0])
    return np.column_stack(
        [np.cumsum(4 * np.cos(heading) * dt), np.cumsum(4 * np.sin(heading) * dt)]
    )


def _case():
    rng = np.random.default_rng(0)
    t = np.arange(0.0, 200.0, 0.2)
    lone = (t >= 120.0) & (t < 122.0)  # a 2 s burst between two dropouts
    keep_t = (t < 90.0) | lone | (t >= 152.0)
    t = t[keep_t]
    truth = _drive(t)
    gps = truth + 0.2 * rng.standard_normal(truth.shape)
    hop = int(np.searchsorted(t, 30.0))
    gps[hop] += [5.0, -3.0]  # a single-sample hop
    offset = (t >= 60.0) & (t < 66.0)  # a 6 s stretch 8 m off
    gps[offset] += [0.0, 8.0]
    # the odometry's track in its own frame, turning slowly away from the truth (0.03 deg/s)
    drift = np.radians(0.03) * t
    rel = truth - truth[0]
    track = np.column_stack(
        [
            np.cos(drift) * rel[:, 0] - np.sin(drift) * rel[:, 1],
            np.sin(drift) * rel[:, 0] + np.cos(drift) * rel[:, 1],
        ]
    )
    track = se2.rotate(-0.7, track) + [100.0, -50.0]
    bad = np.zeros(t.size, bool)
    bad[hop] = True
    bad |= offset
    bad |= (t >= 120.0) & (t < 122.0)  # 10 fixes: fewer than 15 in any window
    return t, gps, track, bad


def test_the_rule_keeps_exactly_the_fixes_it_should():
    t, gps, track, bad = _case()
    keep = vouched_fixes(t, gps, track)
    assert np.array_equal(keep, ~bad), np.flatnonzero(keep != ~bad)


def test_the_rule_needs_no_slam_output_and_ignores_the_frame():
    """Any rigid move of the odometry's track gives the same fixes."""
    t, gps, track, _ = _case()
    moved = se2.rotate(2.0, track) + [-3e3, 7e2]
    assert np.array_equal(vouched_fixes(t, gps, track), vouched_fixes(t, gps, moved))


def test_a_stationary_vehicle_is_judged_by_translation_alone():
    """Parked (the track spans under 2 m): no rotation can be told, only the offset; fixes
    scattered 0.2 m about the spot are kept, one 4 m off is not."""
    rng = np.random.default_rng(1)
    t = np.arange(0.0, 40.0, 0.2)
    track = np.tile([5.0, 5.0], (t.size, 1)) + 0.01 * rng.standard_normal((t.size, 2))
    gps = np.tile([-20.0, 8.0], (t.size, 1)) + 0.2 * rng.standard_normal((t.size, 2))
    gps[50] += [4.0, 0.0]
    keep = vouched_fixes(t, gps, track)
    expected = np.ones(t.size, bool)
    expected[50] = False
    assert np.array_equal(keep, expected)
    assert VouchRule.min_span_m == 2.0 and math.isclose(VouchRule.tol_m, 1.0)


@pytest.mark.slow
def test_the_association_loop_table_and_the_victoria_park_table_agree(vp_dir):
    """The in-the-loop table's Victoria Park IHGR row and the Victoria Park table's run of the
    same scans (1-1500: the --quick head) are one run: equal GPS RMSE, over all fixes and over
    the vouched ones, and the vouched one is a real figure."""
    from experiments.paper import association_loop as al
    from experiments.paper.victoria_park import real_run as vp

    loop = al.victoria_park_trial((1500, al.LOOP_METHODS[0]))
    row, _ = vp.vp_trial(("x", "full", "detections", "ihgr", True, False))
    assert loop["gps_rmse_m"] == pytest.approx(row["rmse_m"], rel=1e-12)
    assert loop["gps_vouched_rmse_m"] == pytest.approx(row["rmse_vouched_m"], rel=1e-12)
    assert 0.3 < loop["gps_vouched_rmse_m"] < loop["gps_rmse_m"]
