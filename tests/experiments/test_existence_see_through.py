"""`existence_rates.derive_see_through`: the see-through rate q of the existence model measured
on a run, without the truth, where the model applies it (a trunk in view and not reported)."""

import numpy as np
import pytest

from experiments.errors import DataError
from experiments.eval.existence_rates import (
    ESTABLISHED,
    _views,
    derive_see_through,
    derive_see_through_by_range,
    see_through_rates,
)
from slam import run_slam
from tests.experiments.test_existence_policy_run import clutter_drive

MIN_BEAMS = 4  # the drive's derived min_beams: geometric's min_circle_points


@pytest.fixture(scope="module")
def run():
    _, seq, cfg, feats = clutter_drive()
    return seq, run_slam(seq, cfg, features=feats)


def test_q_is_the_share_of_beams_passing_beyond_a_trunk_in_the_scans_it_was_missed(run):
    """In the simulated park the landmarks the run keeps are trunks placed within centimetres:
    of the beams reaching them in the scans they were missed, most return from the trunk, so
    q is small but above 0; it is the stated ratio of the counts it reports, and counting the
    detected scans too (where the model ignores the beams) would give a different figure."""
    seq, lg = run
    d = derive_see_through(lg, seq, (0, seq.n_scans), MIN_BEAMS)
    q = d["settings"]["map_policy.existence_see_through_q"]
    assert d["missed_beams_free"] > 20
    assert d["missed_beams_free"] <= d["missed_beams_reaching"]
    assert q == d["missed_beams_through"] / d["missed_beams_free"]
    assert 0 < q < 0.3
    through = reach = 0
    for ev, free, _, _ in _views(lg, seq, (0, seq.n_scans), ESTABLISHED):
        use = free >= MIN_BEAMS
        through, reach = through + ev.through[use].sum(), reach + ev.reach[use].sum()
    assert reach > d["missed_beams_reaching"] and not np.isclose(through / reach, q)


def test_an_occluded_beam_is_not_evidence_q_counts_free_beams_only(monkeypatch):
    """Two views where the landmark was missed with enough free beams: 6 beams reach it, 2 of
    them returned nearer (occluded), 1 passed beyond; and 3 reach, none occluded, 2 passed.
    q is 3 through over the 7 free beams, not over the 9 reaching; a detected view and one
    with fewer than min_beams free beams add nothing."""
    from experiments.eval import existence_rates
    from slam.existence import BeamEvidence

    def views(lg, seq, scans, established, footprint_steps=0.0):
        ev = BeamEvidence(np.array([6, 3, 5, 2]), np.array([2, 0, 0, 1]), np.array([1, 2, 4, 1]))
        hit = np.array([False, False, True, False])
        yield ev, ev.reach - ev.occluded, hit, np.full(4, 10.0)

    monkeypatch.setattr(existence_rates, "_views", views)
    d = derive_see_through(None, None, (0, 1), min_beams=2)
    assert d["missed_beams_reaching"] == 9 and d["missed_beams_free"] == 7
    assert d["missed_beams_through"] == 3
    assert d["settings"]["map_policy.existence_see_through_q"] == 3 / 7


def test_no_missed_established_landmark_derives_nothing_and_says_why(run):
    seq, lg = run
    with pytest.raises(DataError, match="no established landmark was missed"):
        derive_see_through(lg, seq, (0, seq.n_scans), MIN_BEAMS, established=10000)


def test_range_bins_add_up_to_the_beam_rates_and_split_them_by_range(run):
    """`range_detection_rates` over 1 m bins covering every view sums, over its range bins, to
    `beam_detection_rates`' counts; with the bins cut at the median view's range, each half
    holds a share of them, and a view beyond the last edge is not counted."""
    from experiments.eval.existence_rates import beam_detection_rates, range_detection_rates

    seq, lg = run
    scans = (0, seq.n_scans)
    e, d = beam_detection_rates(lg, seq, scans)
    assert e.sum() > 50
    edges = np.arange(0.0, float(seq.scan_max_range) + 1.0, 1.0)
    er, dr = range_detection_rates(lg, seq, scans, edges)
    assert er.sum(axis=0).tolist() == e.tolist() and dr.sum(axis=0).tolist() == d.tolist()
    ranges = np.concatenate([r for *_, r in _views(lg, seq, scans, ESTABLISHED)])
    mid = float(np.median(ranges))
    near, _ = range_detection_rates(lg, seq, scans, np.array([0.0, mid]))
    assert near.sum() == int((ranges < mid).sum()) and 0 < near.sum() < e.sum()


def test_q_by_range_splits_the_pooled_counts_into_range_bins(run):
    """derive_see_through_by_range counts the beams derive_see_through counts, split by the
    landmark's range: per 10 m bin the counts sum to the pooled ones, each bin's q is
    see_through_rates of its counts (the pooled q where a bin has no free beam), and the bins
    cover the view's range."""
    seq, lg = run
    d = derive_see_through(lg, seq, (0, seq.n_scans), MIN_BEAMS)
    b = derive_see_through_by_range(lg, seq, (0, seq.n_scans), MIN_BEAMS, bin_m=10.0)
    free, through = np.array(b["missed_beams_free"]), np.array(b["missed_beams_through"])
    assert free.sum() == d["missed_beams_free"] and through.sum() == d["missed_beams_through"]
    assert (free > 0).sum() >= 2  # the drive's trunks are missed at more than one range
    q = b["settings"]["map_policy.existence_see_through_q_by_range"]
    pooled = d["settings"]["map_policy.existence_see_through_q"]
    assert q == see_through_rates(through, free, pooled).tolist()
    max_range = min(float(seq.scan_max_range), float(lg.config["measurement"]["max_range_m"]))
    assert len(q) == int(np.ceil(max_range / 10.0))
    assert b["settings"]["map_policy.existence_see_through_q_bin_m"] == 10.0
