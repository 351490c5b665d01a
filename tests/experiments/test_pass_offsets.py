"""experiments.eval.pass_offsets: the leave-one-pass-out criterion of the pass offset."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from experiments.errors import DataError
from experiments.eval.pass_offsets import CHI2_1_MEDIAN, Passes, held_out, pass_offset, passes_of
from slam import run_slam, se2
from tests.slam.test_run import LANDMARKS, TIGHT, drive_sequence, paper_noise, point_features

WHITE = (0.03**2, 0.02**2)  # m^2: range, across


def synthetic(seed: int, sd, landmarks: int = 200, wrong: float = 0.0) -> Passes:
    """Passes of `landmarks` trees (2-5 passes each, 3-40 sightings, random sides) whose means
    carry a shared offset of sd = (range, across) on top of white noise of known variance;
    `wrong`: the share of passes that belong to another tree (1-3 m off)."""
    rng = np.random.default_rng(seed)
    lm = np.repeat(np.arange(landmarks), rng.integers(2, 6, landmarks))
    P = lm.size
    c = rng.uniform(-100, 100, (landmarks, 2))
    ang = rng.uniform(-np.pi, np.pi, P)
    u = np.stack([np.cos(ang), np.sin(ang)], 1)
    v = np.stack([-u[:, 1], u[:, 0]], 1)
    n = rng.integers(3, 40, P)
    rr, ra = WHITE[0] * rng.uniform(0.5, 2, P), WHITE[1] * rng.uniform(0.5, 2, P)
    g = rng.standard_normal((4, P, 1))
    xy = c[lm] + sd[0] * g[0] * u + sd[1] * g[1] * v
    xy += np.sqrt(rr / n)[:, None] * g[2] * u + np.sqrt(ra / n)[:, None] * g[3] * v
    bad = rng.random(P) < wrong
    off = rng.uniform(1, 3, bad.sum())[:, None] * u[bad][:, ::-1]
    xy[bad] += off
    return Passes(landmark=lm, n=n, mean_xy=xy, u=u, r_range=rr, r_across=ra)


def test_the_criterion_recovers_a_known_offset_within_its_sampling_error():
    sd = (0.05, 0.03)
    est = np.array([pass_offset(synthetic(seed, sd)).sd_m for seed in range(6)])
    mean, spread = est.mean(axis=0), est.std(axis=0, ddof=1)
    assert np.all(np.abs(mean - sd) < 3 * spread / np.sqrt(len(est)) + 1e-4), (mean, spread)
    assert np.all(spread < 0.2 * np.array(sd))  # and it is informative: 20% per derivation
    got = pass_offset(synthetic(0, sd))
    # at the derived offsets both medians sit at the chi-square(1) median; white far above
    np.testing.assert_allclose(got.median_derived, CHI2_1_MEDIAN, atol=2e-3)
    assert min(got.median_white) > 5 * CHI2_1_MEDIAN


def test_white_passes_give_no_offset():
    for seed in range(4):
        p = synthetic(seed, (0.0, 0.0))
        got = pass_offset(p)
        # the white model's medians scatter around 0.4549, and what is derived is well below
        # the white noise of a typical pass on each axis
        white_sd = np.sqrt(np.median([p.r_range / p.n, p.r_across / p.n], axis=1))
        assert np.all(np.array(got.sd_m) < 0.6 * white_sd), (got, white_sd)
        assert np.all(np.abs(np.array(got.median_white) - CHI2_1_MEDIAN) < 0.1)
        if max(got.median_white) <= CHI2_1_MEDIAN:
            assert got.sd_m == (0.0, 0.0)


def test_a_few_wrong_passes_move_the_median_little():
    """Passes of another tree (a wrong association, 1-3 m off) in 5% of the passes raise s by
    less than 30%, although they also spoil the prediction of their landmark's other passes;
    the mean of the same statistic is the outliers'."""
    sd = (0.05, 0.03)
    clean = np.array(pass_offset(synthetic(1, sd)).sd_m)
    dirty = np.array(pass_offset(synthetic(1, sd, wrong=0.05)).sd_m)
    assert np.all(np.abs(dirty - clean) < 0.3 * clean), (clean, dirty)
    r = held_out(synthetic(1, sd, wrong=0.05), tuple(clean))
    assert np.all(r.mean(axis=0) > 10 * np.median(r, axis=0))


def test_bad_passes_are_clear_errors():
    p = synthetic(0, (0.05, 0.03), landmarks=5)
    xy = p.mean_xy.copy()
    xy[2, 1] = np.nan
    with pytest.raises(DataError, match=r"Passes.mean_xy: values must be finite"):
        dataclasses.replace(p, mean_xy=xy)
    one = np.flatnonzero(np.r_[True, np.diff(p.landmark) != 0])  # each landmark's first pass
    with pytest.raises(DataError, match="at least two passes"):
        Passes(
            landmark=p.landmark[one],
            n=p.n[one],
            mean_xy=p.mean_xy[one],
            u=p.u[one],
            r_range=p.r_range[one],
            r_across=p.r_across[one],
        )


def _log():
    seq = drive_sequence(1.5, 0.05, n_scans=30)
    feats = point_features(seq, LANDMARKS, np.random.default_rng(3))
    return run_slam(seq, paper_noise(TIGHT), features=feats, warm_up=False)


def test_passes_of_a_run_are_its_sightings_means():
    log = _log()
    # a gap shorter than a scan: every sighting is a pass of its own
    p = passes_of(log, gap_s=0.1)
    used = log.meas_status >= 0
    assert p.landmark.size == used.sum() and np.all(p.n == 1)
    world = se2.observed_points(log.pose[log.meas_scan[used]], log.meas_z[used], log.laser_pose)
    order = np.lexsort((log.scan_t[log.meas_scan[used]], log.meas_track[used]))
    np.testing.assert_allclose(p.mean_xy, world[order])
    rng2 = log.meas_z[used, 0] ** 2
    np.testing.assert_allclose(p.r_across, (rng2 * log.meas_R[used, 1, 1])[order])
    # the same run's sightings, one pass per landmark: nothing to hold out
    with pytest.raises(DataError, match="at least two passes"):
        passes_of(log, gap_s=2.0)
    bad = dataclasses.replace(log, meas_z=log.meas_z.copy())
    bad.meas_z[np.flatnonzero(used)[3], 0] = np.nan
    with pytest.raises(DataError, match="meas_z has NaN"):
        passes_of(bad, gap_s=0.1)
