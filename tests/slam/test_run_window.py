"""slam.run_slam with association "ihgr-window": the K-scan IHGR window inside the loop."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from slam import SlamConfig, SlamError, run_slam
from slam.config import AssociationConfig, MeasurementConfig
from slam.log import AMBIGUOUS, CONFIRMED, NEW_TENTATIVE
from slam.smoother import problem_from_log

from .test_run import LANDMARKS, TIGHT, drive_sequence, point_features


def window(K: int, noise=None) -> SlamConfig:
    """The K-scan window, and `noise` as the constant noise of the tests' "paper" circles."""
    m = MeasurementConfig() if noise is None else MeasurementConfig(constant_noise={"paper": noise})
    return SlamConfig(association=AssociationConfig(window_scans=K), measurement=m)


@pytest.mark.parametrize("K", [2, 3, 4])
def test_window_maps_each_landmark_once_from_its_track(K):
    seq = drive_sequence(1.5, 0.0, n_scans=30)
    feats = point_features(seq, LANDMARKS, np.random.default_rng(0))
    log = run_slam(seq, features=feats, association="ihgr-window", config=window(K, TIGHT))
    assert log.association_method == "ihgr-window"
    need = min(3, K)  # the map policy's 3 sightings, at most the window's K scans
    for k in range(need - 1):  # first sightings stay open in the window
        assert np.all(log.meas_status[log.meas_scan == k] == NEW_TENTATIVE)
    assert np.all(log.meas_status[log.meas_scan == need - 1] == CONFIRMED)
    assert np.all(log.meas_status[log.meas_scan >= need] >= 0)
    assert log.landmark_xy.shape[0] == 4
    d = np.hypot(*(log.landmark_xy[:, None, :] - LANDMARKS[None]).transpose(2, 0, 1))
    assert np.all(d.min(axis=1) < 0.05) and len(set(d.argmin(axis=1))) == 4
    assert np.all(log.landmark_first_scan == need - 1)
    # the track's earlier sightings carry the landmark's id (the smoother's "all" measurements)
    for lid in log.landmark_id:
        early = (log.meas_track == lid) & (log.meas_status == NEW_TENTATIVE)
        assert sorted(log.meas_scan[early].tolist()) == list(range(need - 1))
    assert problem_from_log(log, "all").meas_scan.size == problem_from_log(
        log, "ekf"
    ).meas_scan.size + 4 * (need - 1)
    st = log.window_stats
    assert st["K"] == K and st["steps"] == 30
    assert 0 <= st["fractional_lps"] <= st["steps"] and st["track_hypotheses"] >= 4


def test_window_does_not_map_a_ghost_seen_in_two_scans():
    seq = drive_sequence(1.5, 0.0, n_scans=20)
    ghost = {5: [(6.0, 1.0)], 6: [(5.76, 1.0)]}  # a bush seen in two scans only
    feats = point_features(seq, LANDMARKS, np.random.default_rng(1), extra=ghost)
    log = run_slam(seq, features=feats, association="ihgr-window", config=window(3))
    assert log.landmark_xy.shape[0] == 4
    for k in (5, 6):
        last = (log.meas_scan == k) & (
            log.meas_feature == log.meas_feature[log.meas_scan == k].max()
        )
        assert log.meas_status[last][0] == NEW_TENTATIVE
    # with K = 2 two sightings are enough: the window maps it (the price of a short window)
    log2 = run_slam(seq, features=feats, association="ihgr-window", config=window(2))
    assert log2.landmark_xy.shape[0] == 5


def test_window_says_when_it_cannot_wait_for_confirm_scans(caplog):
    """The window confirms on min(K, confirm_scans) sightings: asked for more scans than it
    holds, it says so, and maps the ghost of two sightings as K = 2 does."""
    seq = drive_sequence(1.5, 0.0, n_scans=20)
    ghost = {5: [(6.0, 1.0)], 6: [(5.76, 1.0)]}
    feats = point_features(seq, LANDMARKS, np.random.default_rng(1), extra=ghost)
    cfg = window(2).with_(**{"map_policy.confirm_scans": 4})
    with caplog.at_level("WARNING", logger="slam.map_managers"):
        log = run_slam(seq, features=feats, association="ihgr-window", config=cfg)
    assert "confirm_scans = 4 but the 'ihgr-window' association holds 2 scans" in caplog.text
    assert log.landmark_xy.shape[0] == 5
    caplog.clear()
    with caplog.at_level("WARNING", logger="slam.map_managers"):
        run_slam(seq, features=feats, association="ihgr-window", config=window(3))
    assert "ihgr-window" not in caplog.text  # the defaults, 3 and 3: nothing to say


def test_window_ignores_an_ambiguous_measurement_near_a_mapped_landmark():
    seq = drive_sequence(1.5, 0.0, n_scans=12)
    feats = point_features(seq, LANDMARKS, np.random.default_rng(2), sigma=(0.002, 0.0002))
    k = 8  # landmark 0 is mapped by now; add a measurement 8 cm beside its true centre
    c = feats[k].circle_params[0]
    r = np.hypot(c[0], c[1])
    extra = c[:2] + 0.08 * np.array([-c[1], c[0]]) / r
    params = np.vstack([feats[k].circle_params, [*extra, 0.3]])
    feats[k] = dataclasses.replace(
        feats[k],
        circle_params=params,
        circle_cov=np.zeros((len(params), 3, 3)),
        circle_beams=np.zeros((len(params), 2), np.int64),
        circle_rms_m=np.zeros(len(params)),
    )
    cfg = window(3, TIGHT._replace(range_sigma_m=0.002, bearing_sigma_rad=2e-4))
    log = run_slam(seq, features=feats, association="ihgr-window", config=cfg)
    row = (log.meas_scan == k) & (log.meas_feature == len(params) - 1)
    assert log.meas_status[row][0] == AMBIGUOUS
    assert log.landmark_xy.shape[0] == 4


def test_window_decisions_do_not_depend_on_measurement_order():
    """The same scans with each scan's circles in a random order: the same pairings, map and
    path (up to the rounding of the batch update's sums)."""
    from experiments.paper.slam import extractor_params
    from experiments.sim.trajectory import CycabParams, simulate_cycab_run
    from features import extract_features

    cyc = CycabParams(n_scans=100, speed_sigma_mps=0.2, steer_sigma_rad=np.radians(4.0))
    seq = simulate_cycab_run(np.random.default_rng(11), "tree_park", cyc)
    params = extractor_params("paper", cyc)
    feats = [extract_features(seq.scan(k), "paper", **params) for k in range(seq.n_scans)]
    rng = np.random.default_rng(3)
    perms, shuffled = [], []
    for f in feats:
        p = rng.permutation(f.n_circles)
        perms.append(p)
        shuffled.append(
            dataclasses.replace(
                f,
                circle_params=f.circle_params[p],
                circle_cov=f.circle_cov[p],
                circle_beams=f.circle_beams[p],
                circle_rms_m=f.circle_rms_m[p],
            )
        )
    cfg = window(3)
    a = run_slam(seq, features=feats, association="ihgr-window", config=cfg)
    b = run_slam(seq, features=shuffled, association="ihgr-window", config=cfg)
    assert a.landmark_xy.shape[0] == b.landmark_xy.shape[0] >= 6
    np.testing.assert_allclose(a.pose, b.pose, atol=1e-9)
    np.testing.assert_allclose(
        np.sort(a.landmark_xy, axis=0), np.sort(b.landmark_xy, axis=0), atol=1e-9
    )
    # measurement i of scan k in `a` is measurement inv[k][i] of `b`: same status kind
    kind_a = np.sign(a.meas_status)
    kind_b = np.sign(b.meas_status)
    for k, p in enumerate(perms):
        inv = np.argsort(p)
        ra = np.flatnonzero(a.meas_scan == k)
        rb = np.flatnonzero(b.meas_scan == k)
        np.testing.assert_array_equal(kind_a[ra], kind_b[rb][inv])
        np.testing.assert_array_equal(a.meas_status[ra] < 0, b.meas_status[rb][inv] < 0)
    assert a.obs_scan.size == b.obs_scan.size


def test_window_settings_are_checked():
    seq = drive_sequence(1.5, 0.0, n_scans=5)
    feats = point_features(seq, LANDMARKS, np.random.default_rng(0))
    with pytest.raises(SlamError, match="association.window_scans"):
        AssociationConfig(window_scans=0)
    with pytest.raises(SlamError, match="association.window_scans"):
        SlamConfig.from_dict({"association": {"window_scans": 2.5}})
    assert SlamConfig.from_dict({"association": {"window_scans": 4}}).association.window_scans == 4
    with pytest.raises(SlamError, match="association.params: .*max_nodes"):  # at once
        AssociationConfig(params={"max_nodes": 10})
    jcbb = SlamConfig(association=AssociationConfig(method="jcbb", params={"max_nodes": 10}))
    with pytest.raises(SlamError, match="max_nodes"):  # the method given to run_slam: checked
        run_slam(seq, features=feats, association="ihgr-window", config=jcbb)
    with pytest.raises(SlamError, match="ihgr-window"):
        run_slam(seq, features=feats, association="window")
