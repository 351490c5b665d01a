"""The published RFS protocol (experiments/eval/rfs_protocol.py) and its experiment
(experiments/paper/victoria_park/rfs.py): the clutter generator, the FOV cut, the 25 ms rule
scored at the laser, the fixed start, and the experiment's quick path on the real data."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from experiments.eval.rfs_protocol import (
    RfsProtocol,
    fov_cut,
    nearest_fix,
    poisson_clutter,
    pooled_rmse,
    score_at_scans,
)
from slam import se2

P = RfsProtocol()
LASER = np.array([3.78, 0.5, -0.0187])


def test_clutter_count_is_poisson_with_mean_five_per_scan():
    """20,000 scans: the count's mean and variance within 4 standard errors of 5 (a Poisson
    count's variance is its mean); scans not listed get none."""
    scans = np.arange(0, 40_000, 2)
    scan, _, _ = poisson_clutter(np.random.default_rng(1), scans, P)
    counts = np.bincount(scan, minlength=40_000)
    assert counts[1::2].sum() == 0
    c = counts[scans]
    n = c.size
    assert abs(c.mean() - 5.0) < 4 * math.sqrt(5.0 / n)
    # the variance of a sample variance of a Poisson(5) count: (mu + 2 mu^2) / n
    assert abs(c.var() - 5.0) < 4 * math.sqrt((5.0 + 2 * 25.0) / n)


def test_clutter_is_uniform_in_range_and_bearing_over_the_cut_field_of_view():
    _, r, b = poisson_clutter(np.random.default_rng(2), np.arange(4000), P)
    assert r.size > 15_000
    assert r.min() >= 0 and r.max() <= 50.0
    assert np.abs(b).max() <= math.radians(85.0)
    assert fov_cut(r, b, P).all()
    # Kolmogorov-Smirnov against the uniform laws their code draws from (rand * range)
    assert stats.kstest(r, stats.uniform(0, 50).cdf).pvalue > 1e-3
    lo = -math.radians(85.0)
    assert stats.kstest(b, stats.uniform(lo, -2 * lo).cdf).pvalue > 1e-3
    # and the range is uniform in range, not in area: half the points within 25 m
    assert abs(np.mean(r <= 25.0) - 0.5) < 0.02


def test_clutter_is_determined_by_its_seed():
    scans = np.arange(100)
    a = poisson_clutter(np.random.default_rng(np.random.SeedSequence(7)), scans, P)
    b = poisson_clutter(np.random.default_rng(np.random.SeedSequence(7)), scans, P)
    c = poisson_clutter(np.random.default_rng(np.random.SeedSequence(8)), scans, P)
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x, y)
    assert a[0].size != c[0].size or not np.array_equal(a[1], c[1])


def test_fov_cut_keeps_50_m_and_85_degrees():
    r = np.array([49.9, 50.0, 50.01, 10.0, 10.0, 10.0])
    b = np.radians([0.0, 0.0, 0.0, 85.0, -85.0, 85.01])
    np.testing.assert_array_equal(fov_cut(r, b, P), [True, True, False, True, True, False])


def test_a_scan_is_scored_against_the_nearest_fix_only_within_25_ms():
    gps_t = np.array([0.0, 0.2, 0.4, 0.6])
    gps_xy = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [3.0, 0.0]])
    scan_t = np.array([0.02, 0.03, 0.17, 0.3, 0.599])
    est = np.array([[0.0, 1.0], [0.0, 1.0], [1.0, 2.0], [5.0, 5.0], [3.0, -0.5]])
    idx, dt = nearest_fix(scan_t, gps_t)
    np.testing.assert_array_equal(idx, [0, 0, 1, 1, 3])  # 0.3: a tie, the earlier fix
    np.testing.assert_allclose(dt, [0.02, 0.03, 0.03, 0.1, 0.001])
    e = score_at_scans(scan_t, est, gps_t, gps_xy)
    np.testing.assert_allclose(e[[0, 4]], [1.0, 0.5])
    assert np.isnan(e[[1, 2, 3]]).all()
    assert pooled_rmse([e[:2], e[2:]]) == pytest.approx(math.sqrt((1.0 + 0.25) / 2))
    assert math.isnan(pooled_rmse([np.array([np.nan])]))


def test_the_score_is_taken_at_the_laser_not_at_the_rear_axle():
    """A path whose laser passes exactly through the fixes scores 0; its rear axle, the
    laser's offset (3.81 m)."""
    t = np.arange(20) * 0.2
    pose = np.column_stack([2.0 * t, 0.5 * t, np.full(t.size, 0.4)])
    laser = np.array([se2.compose(p, LASER)[:2] for p in pose])
    e_laser = score_at_scans(t, laser, t + 0.01, laser)
    e_axle = score_at_scans(t, pose[:, :2], t + 0.01, laser)
    np.testing.assert_allclose(e_laser, 0.0, atol=1e-12)
    np.testing.assert_allclose(e_axle, math.hypot(3.78, 0.5))


def test_the_fixed_start_puts_the_laser_at_the_published_pose():
    from experiments.paper.victoria_park.rfs import start_prior

    """The laser's pose, position and heading, is the published start (their state is the
    laser's pose; our laser is yawed on the vehicle, so the vehicle's heading differs)."""
    pose, cov = start_prior(LASER)
    x, y, h = P.start_laser
    assert h == pytest.approx(math.radians(35.5))
    np.testing.assert_allclose(se2.compose(pose, LASER), [x, y, h], atol=1e-12)
    assert pose[2] == pytest.approx(h - LASER[2], abs=1e-15)
    np.testing.assert_array_equal(cov, np.zeros((3, 3)))


def test_protocol_constants_are_checked():
    for bad in (
        {"fov_range_m": 0.0},
        {"clutter_rate": -1.0},
        {"draws": 0},
        {"tolerance_s": math.nan},
    ):
        with pytest.raises(ValueError, match="RfsProtocol"):
            RfsProtocol(**bad)


@pytest.mark.slow
@pytest.mark.data
def test_quick_experiment_writes_the_protocol_beside_no_clutter_and_vouched(vp_dir, tmp_path):
    """--quick end to end, on the first 800 scans (the protocol's input made from their raw
    laser and published detections as for the whole run): its clutter draws (different
    clutter, the same scans scored), the run without clutter and victoria-park's; the pooled
    RMSE is the RMS of the draws' (they score the same scans), and the clutter adds about 5
    false detections per scan."""
    from experiments.io.victoria_park import load_victoria_park
    from experiments.io.writers import read_tidy_csv
    from experiments.paper.reproduce import run_experiments
    from experiments.paper.victoria_park import rfs
    from experiments.paper.victoria_park.real_run import head, run_config

    QUICK_DRAWS, ROWS = rfs.QUICK_DRAWS, rfs.ROWS
    full, raw = load_victoria_park(vp_dir, full=True), load_victoria_park(vp_dir)
    cfg = run_config("detections", "ihgr")
    short = (rfs.protocol_input(head(full, 800), head(raw, 400), cfg), cfg)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(rfs, "_data", lambda quick: short)
        run_experiments(["victoria-park-rfs"], tmp_path, quick=True)
    draws = read_tidy_csv(tmp_path / "victoria_park_rfs_draws.csv")
    summary = {r["run"]: r for r in read_tidy_csv(tmp_path / "victoria_park_rfs.csv")}
    assert set(summary) == set(ROWS.values())
    clutter = [r for r in draws if r["run"] == ROWS["clutter"]]
    assert len(clutter) == QUICK_DRAWS == summary[ROWS["clutter"]]["runs"]
    assert len({r["clutter"] for r in clutter}) == QUICK_DRAWS  # each draw its own clutter
    assert len({r["scans_scored"] for r in clutter}) == 1
    pooled = math.sqrt(np.mean([r["rmse_protocol_m"] ** 2 for r in clutter]))
    assert summary[ROWS["clutter"]]["rmse_protocol_m"] == pytest.approx(pooled, rel=1e-9)
    assert 4.5 < summary[ROWS["clutter"]]["clutter_per_scan"] < 5.5
    for row in summary.values():
        assert 0.0 < row["rmse_protocol_m"] < 20.0 and 0.0 < row["rmse_vouched_m"] < 20.0
    assert summary[ROWS["no clutter"]]["runs"] == 1


def test_clutter_joins_the_scans_with_detections_only_and_keeps_them_in_scan_order():
    """`with_clutter`: the detector's scans get the draw's false detections (radius unknown),
    the others none; the real detections are all still there; the draw is its seed's."""
    from support import full_kwargs

    from experiments.paper.victoria_park.rfs import ProtocolInput, with_clutter
    from slam import Sequence

    seq = Sequence(**{**full_kwargs(), "det_cov": None})
    detected = np.bincount(seq.det_scan, minlength=seq.n_scans) > 0
    inp = ProtocolInput(seq, detected, seq, 0)
    out, n = with_clutter(inp, np.random.default_rng(3))
    again, _ = with_clutter(inp, np.random.default_rng(3))
    np.testing.assert_array_equal(out.det_range, again.det_range)
    assert n == out.det_scan.size - seq.det_scan.size > 0
    assert np.all(np.diff(out.det_scan) >= 0)
    assert set(out.det_scan) == set(seq.det_scan)  # scans 0, 2, 4 only
    pairs = set(zip(out.det_scan, out.det_range, out.det_bearing, strict=True))
    assert all(p in pairs for p in zip(seq.det_scan, seq.det_range, seq.det_bearing, strict=True))
    assert np.isnan(out.det_radius).sum() == n + np.isnan(seq.det_radius).sum()
