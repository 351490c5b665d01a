"""`existence_rates.derive_see_through_by_range` / `derive_see_through`: a view's range bin
is the filter's (`slam.existence.range_bin`), and the beam footprint reaches the count
through `_views` (`map_policy.existence_see_through_footprint`)."""

import math
from types import SimpleNamespace

import numpy as np
import pytest

from experiments.eval import existence_rates
from experiments.eval.existence_rates import derive_see_through, derive_see_through_by_range
from slam.existence import BeamEvidence

SEQ = SimpleNamespace(scan_max_range=40.0)
LG = SimpleNamespace(config={"measurement": {"max_range_m": 80.0}})


def test_a_view_at_9_99_m_lands_in_bin_0_and_one_at_10_m_in_bin_1(monkeypatch):
    """Two missed landmarks, 3 and 4 free beams, 1 and 2 of them through: the first bin
    holds the one at 9.99 m, the second the one at 10.0 m; bins with no free beam take the
    pooled q 3 / 7 of the summed counts."""

    def views(lg, seq, scans, established, footprint_steps=0.0):
        ev = BeamEvidence(np.array([3, 4]), np.array([0, 0]), np.array([1, 2]))
        yield ev, ev.reach - ev.occluded, np.zeros(2, bool), np.array([9.99, 10.0])

    monkeypatch.setattr(existence_rates, "_views", views)
    b = derive_see_through_by_range(LG, SEQ, (0, 1), min_beams=2, bin_m=10.0)
    assert b["missed_beams_free"] == [3, 4, 0, 0]
    assert b["missed_beams_through"] == [1, 2, 0, 0]
    q = b["settings"]["map_policy.existence_see_through_q_by_range"]
    assert q == pytest.approx([1 / 3, 2 / 4, 3 / 7, 3 / 7], rel=1e-15)


def _one_trunk_run():
    """A landmark of radius 0.3 m at 35 m straight ahead (asin(0.3 / 35) = 0.491 deg), missed
    in scan 1, whose 7 beams at 0.2 + 0.5 i deg all return nothing: two beams reach it, at
    -0.3 and 0.2 deg; with half a beam step of footprint only the one at 0.2 deg counts."""
    lg = SimpleNamespace(
        config={"measurement": {"max_range_m": 80.0}},
        landmark_n_obs=np.array([100]),
        landmark_id=np.array([7]),
        landmark_xy=np.array([[35.0, 0.0]]),
        landmark_first_scan=np.array([0]),
        meas_radius_m=np.array([0.3]),
        meas_track=np.array([7]),
        obs_scan=np.array([0]),
        obs_landmark=np.array([7]),
        n_scans=2,
        scan_skipped=np.zeros(2, bool),
        pose=np.zeros((2, 3)),
        laser_pose=np.zeros(3),
    )
    scan = SimpleNamespace(
        ranges_m=np.full(7, math.nan),
        angle_min_rad=math.radians(0.2 - 1.5),
        angle_increment_rad=math.radians(0.5),
    )
    seq = SimpleNamespace(scan_max_range=80.0, scan=lambda k: scan)
    return lg, seq


def test_the_footprint_changes_the_derived_count_through_the_views():
    lg, seq = _one_trunk_run()
    plain = derive_see_through(lg, seq, (1, 2), min_beams=2)
    assert (plain["missed_beams_free"], plain["missed_beams_through"]) == (2, 2)
    assert plain["settings"]["map_policy.existence_see_through_q"] == 1.0
    foot = derive_see_through(lg, seq, (1, 2), min_beams=2, footprint_steps=0.5)
    assert (foot["missed_beams_free"], foot["missed_beams_through"]) == (2, 1)
    assert foot["settings"]["map_policy.existence_see_through_q"] == 0.5
    b = derive_see_through_by_range(lg, seq, (1, 2), 2, bin_m=10.0, footprint_steps=0.5)
    assert b["missed_beams_free"] == [0, 0, 0, 2, 0, 0, 0, 0]  # 35 m: bin 3 of 8
    assert b["missed_beams_through"] == [0, 0, 0, 1, 0, 0, 0, 0]
