"""Persistent clutter's repeat rate and the birth by range on a simulated drive: derived per
range bin from the run's own tracks (`experiments.eval.existence_rates.derive_repeat_by_range`,
`derive_birth_by_range`; no truth), and used by the run's map loop in place of the single
rate (`slam.existence_map`)."""

import numpy as np
import pytest

from experiments.errors import DataError
from experiments.eval.existence_rates import (
    derive_birth_by_range,
    derive_existence,
    derive_persistent,
    derive_repeat_by_range,
    truncated_geometric_p,
)
from slam import run_slam
from slam.existence import range_bin
from tests.experiments.test_existence_policy_run import clutter_drive


@pytest.fixture(scope="module")
def drive():
    scene, seq, cfg, feats = clutter_drive()
    return seq, cfg, feats, run_slam(seq, cfg, features=feats)


def test_each_bin_holds_the_never_mapped_tracks_at_its_range_and_their_runs_rate(drive):
    """The bins' tracks sum to derive_persistent's never-mapped tracks, each bin's rate is the
    truncated estimate of the runs of the tracks whose median range lies in it, an empty bin
    takes the pooled rate (derive_persistent's), and the bins cover the view's range."""
    seq, cfg, _, lg = drive
    h = (0, seq.n_scans)
    d = derive_repeat_by_range(lg, seq, h, bin_m=5.0)
    p = derive_persistent(lg, h)
    counts = d["never_mapped_tracks_by_bin"]
    assert sum(counts) == p["never_mapped_tracks"] > 0
    assert d["pooled_repeat_prob"] == p["settings"]["map_policy.existence_repeat_prob"]
    rates = d["settings"]["map_policy.existence_repeat_prob_by_range"]
    far = min(seq.scan_max_range, cfg.measurement.max_range_m)
    assert len(rates) == int(np.ceil(far / 5.0)) == len(counts)
    tracks = np.array(sorted(set(lg.meas_track[lg.meas_track >= 0].tolist())))
    never = tracks[~np.isin(tracks, lg.landmark_id)]
    rng = [np.median(lg.meas_z[lg.meas_track == t, 0]) for t in never]
    runs = np.array([np.count_nonzero(lg.meas_track == t) for t in never])
    b = range_bin(np.array(rng), 5.0, len(rates))
    cut = cfg.map_policy.confirm_scans - 1
    for i, (rate, n) in enumerate(zip(rates, counts)):
        assert n == np.count_nonzero(b == i)
        want = truncated_geometric_p(runs[b == i], cut) if n else d["pooled_repeat_prob"]
        assert rate == want and 0 < rate < 1
    with pytest.raises(DataError, match="bin_m"):
        derive_repeat_by_range(lg, seq, h, bin_m=0.0)


def test_the_loop_weighs_each_landmark_against_its_bins_rate(drive):
    """Without Pd's fall-off, a one-bin table of the single rate is the single rate: the run is
    the same to the bit; a table whose far bins re-report more changes the map's existence."""
    seq, cfg, feats, _ = drive
    ex = cfg.with_(
        **{
            "map_policy.policy": "existence",
            "map_policy.existence_clutter": "persistent",
            "map_policy.existence_repeat_prob": 0.3,
        }
    )
    a = run_slam(seq, ex, features=feats)
    b = run_slam(
        seq, ex.with_(**{"map_policy.existence_repeat_prob_by_range": [0.3]}), features=feats
    )
    np.testing.assert_array_equal(a.landmark_xy, b.landmark_xy)
    np.testing.assert_array_equal(a.landmark_existence, b.landmark_existence)
    far = ex.with_(**{"map_policy.existence_repeat_prob_by_range": [0.3, 0.9]})
    c = run_slam(seq, far, features=feats)
    assert not np.array_equal(a.landmark_existence, c.landmark_existence)


def test_each_birth_bin_holds_the_tracks_started_at_its_range_and_their_share_joined(drive):
    """The bins' started tracks sum to derive_existence's, their joined ones too, each bin's
    birth is its share (the pooled where none started), and a one-bin table of the single birth
    runs the same to the bit as the single birth."""
    seq, cfg, feats, lg = drive
    h = (0, seq.n_scans)
    d = derive_birth_by_range(lg, seq, h, bin_m=5.0)
    e = derive_existence(lg, seq, h)
    started, joined = d["tracks_started_by_bin"], d["tracks_joined_by_bin"]
    assert sum(started) == e["tracks_started"] > 0 and sum(joined) == e["tracks_joined"]
    birth = d["settings"]["map_policy.existence_birth_prob_by_range"]
    assert d["pooled_birth_prob"] == e["settings"]["map_policy.existence_birth_prob"]
    for b, n, k in zip(birth, started, joined):
        assert b == min(max(k / n if n else d["pooled_birth_prob"], 1e-6), 1.0 - 1e-6)
    assert any(n == 0 for n in started) and len(set(birth)) > 1  # both cases are exercised
    with pytest.raises(DataError, match="bin_m"):
        derive_birth_by_range(lg, seq, h, bin_m=-1.0)
    ex = cfg.with_(**{"map_policy.policy": "existence", "map_policy.existence_birth_prob": 0.2})
    a = run_slam(seq, ex, features=feats)
    b = run_slam(
        seq, ex.with_(**{"map_policy.existence_birth_prob_by_range": [0.2]}), features=feats
    )
    np.testing.assert_array_equal(a.landmark_existence, b.landmark_existence)
    far = ex.with_(**{"map_policy.existence_birth_prob_by_range": [0.2, 0.2, 1e-4]})
    assert run_slam(seq, far, features=feats).landmark_id.size < a.landmark_id.size


def test_a_bin_whose_every_track_joined_derives_just_below_one_not_one():
    """Tracks 1 and 2 start at 5 m and both join, track 3 starts at 25 m (seen again at 15 m)
    and does not: bin 0 would be 1, an existence no evidence lowers, and is 1 - 1e-6; the track
    seen again nearer stays in its first sighting's bin (bin 2: 0 clipped to 1e-6)."""
    from types import SimpleNamespace

    from slam import SlamConfig
    from slam.errors import SlamError
    from slam.log import NEW_TENTATIVE

    lg = SimpleNamespace(
        meas_scan=np.array([0, 0, 0, 1]),
        meas_status=np.full(4, NEW_TENTATIVE),
        meas_track=np.array([1, 2, 3, 3]),
        meas_z=np.array([[5.0, 0.0], [5.0, 0.1], [25.0, 0.2], [15.0, 0.2]]),
        landmark_id=np.array([1, 2]),
        departures=[],
        config={"measurement": {"max_range_m": 30.0}},
    )
    d = derive_birth_by_range(lg, SimpleNamespace(scan_max_range=30.0), (0, 2), bin_m=10.0)
    assert d["tracks_started_by_bin"] == [2, 0, 1]
    birth = d["settings"]["map_policy.existence_birth_prob_by_range"]
    assert birth[0] == 1.0 - 1e-6 and birth[2] == 1e-6
    SlamConfig().with_(**{"map_policy.existence_birth_prob_by_range": birth})  # accepted
    with pytest.raises(SlamError, match="existence_birth_prob_by_range"):
        SlamConfig().with_(**{"map_policy.existence_birth_prob_by_range": [1.0, *birth[1:]]})


def test_the_tables_are_accepted_and_ignored_where_their_model_is_off(drive):
    """As existence_repeat_prob: the repeat table changes nothing with uniform clutter, and
    neither table changes the confirm policy's run (`MapPolicy` doc)."""
    seq, cfg, feats, lg = drive
    repeat = {"map_policy.existence_repeat_prob_by_range": [0.1, 0.9]}
    birth = {"map_policy.existence_birth_prob_by_range": [0.5, 1e-4]}
    ex = cfg.with_(**{"map_policy.policy": "existence", "map_policy.existence_clutter": "uniform"})
    a = run_slam(seq, ex, features=feats)
    b = run_slam(seq, ex.with_(**repeat), features=feats)
    np.testing.assert_array_equal(a.landmark_existence, b.landmark_existence)
    np.testing.assert_array_equal(a.landmark_xy, b.landmark_xy)
    assert cfg.map_policy.policy == "confirm"
    c = run_slam(seq, cfg.with_(**repeat, **birth), features=feats)
    np.testing.assert_array_equal(lg.landmark_xy, c.landmark_xy)
    np.testing.assert_array_equal(lg.landmark_id, c.landmark_id)
    # the same tables do act where their model is on: the tests above
