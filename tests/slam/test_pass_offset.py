"""The pass offset (`measurement.pass_offset_sd_m`): a trunk's centre offset shared by the
sightings of one pass, in the filter's update (`slam.loop.Slam.update`), the run's history
(`RunHistory.pass_index`) and the smoother's problem (`slam.smoother.problem_from_log`)."""

from __future__ import annotations

import numpy as np
import pytest

from slam import SlamConfig, SlamError, run_slam
from slam.ekf import Filter
from slam.history import RunHistory
from slam.measurement import pass_inflation, pass_sizes, pass_variance
from slam.smoother import problem_from_log, smooth
from tests.slam.test_run import LANDMARKS, TIGHT, drive_sequence, paper_noise, point_features


@pytest.mark.parametrize("r", [1e-4, 0.01, 0.3])
@pytest.mark.parametrize("s", [0.0, 0.02, 0.1])
def test_a_pass_carries_the_information_of_sightings_that_share_an_offset(r, s):
    """Sequential: the first k sightings together carry k / (r + k s^2), for every k; batch:
    n sightings of r + n s^2 carry the same."""
    n = np.arange(1, 41)
    info = np.cumsum(1.0 / pass_variance(r, n, s))
    np.testing.assert_allclose(info, n / (r + n * s**2), rtol=1e-12)
    np.testing.assert_allclose(n / pass_variance(r, n, s, batch=True), n / (r + n * s**2))
    assert pass_variance(r, 1, s) == pytest.approx(r + s**2)


def test_a_zero_offset_adds_exactly_nothing_and_the_correlation_is_kept():
    z = np.array([[10.0, 0.2], [4.0, -1.0]])
    R = np.array([[[0.01, 0.001], [0.001, 1e-5]], [[0.02, 0.0], [0.0, 4e-6]]])
    k = np.array([3, 7])
    np.testing.assert_array_equal(pass_inflation(z, R, k, (0.0, 0.0)), R)
    out = pass_inflation(z, R, k, (0.0, 0.05))
    np.testing.assert_array_equal(out[:, 0], R[:, 0])  # the range axis untouched
    np.testing.assert_array_equal(out[:, 1, 0], R[:, 1, 0])
    across = z[:, 0] ** 2 * R[:, 1, 1]  # the bearing variance in metres
    np.testing.assert_allclose(out[:, 1, 1] * z[:, 0] ** 2, pass_variance(across, k, 0.05))
    out = pass_inflation(z, R, k, (0.1, 0.0), batch=True)
    np.testing.assert_allclose(out[:, 0, 0], R[:, 0, 0] + k * 0.01)
    np.testing.assert_array_equal(out[:, 1, 1], R[:, 1, 1])


def test_passes_end_after_the_gap_per_landmark():
    t = np.array([0.0, 0.5, 1.0, 0.2, 4.0, 4.5, 1.2, 10.0])
    lm = np.array([1, 1, 1, 2, 1, 1, 2, 2])
    number, size = pass_sizes(t, lm, 2.0)
    # landmark 1: {0, 0.5, 1.0} and {4.0, 4.5}; landmark 2: {0.2, 1.2} and {10}
    assert size.tolist() == [3, 3, 3, 2, 2, 2, 2, 1]
    assert len(set(number.tolist())) == 4
    assert number[0] == number[2] != number[4] == number[5]
    h = RunHistory(np.arange(3.0))
    got = [h.pass_index([1, 2], t, 2.0).tolist() for t in (0.0, 1.0, 2.5, 5.0)]
    assert got == [[1, 1], [2, 2], [3, 3], [1, 1]]  # 2.5 s after 0 but 1.5 s after the last


@pytest.mark.parametrize(
    ("value", "message"),
    [
        ({"pass_offset_sd_m": [0.1]}, r"measurement\.pass_offset_sd_m: expected"),
        ({"pass_offset_sd_m": [0.1, -0.1]}, r"pass_offset_sd_m\[1\]: must be a finite number >= 0"),
        ({"pass_offset_sd_m": [float("nan"), 0.0]}, r"pass_offset_sd_m\[0\]"),
        ({"pass_offset_sd_m": [20.0, 0.0]}, r"pass_offset_sd_m\[0\]: must be 0 or"),
        ({"pass_offset_sd_m": [True, 0.0]}, r"pass_offset_sd_m\[0\]: expected a number"),
        ({"pass_gap_s": 0.0}, r"pass_gap_s: must be > 0"),
        ({"pass_gap_s": float("inf")}, r"pass_gap_s"),
    ],
)
def test_bad_pass_settings_name_the_key(value, message):
    with pytest.raises(SlamError, match=message):
        SlamConfig.from_dict({"measurement": value})


def _run(sd, gap=2.0, monkeypatch=None, seen=None):
    seq = drive_sequence(1.5, 0.05, n_scans=40)
    feats = point_features(seq, LANDMARKS, np.random.default_rng(3))
    cfg = paper_noise(TIGHT, **{"measurement.pass_offset_sd_m": sd, "measurement.pass_gap_s": gap})
    if monkeypatch is not None:
        update = Filter.update

        def spy(self, pos, z, R, laser):
            seen.append((self.landmark_ids[pos].copy(), z.copy(), R.copy()))
            return update(self, pos, z, R, laser)

        monkeypatch.setattr(Filter, "update", spy)
    return run_slam(seq, cfg, features=feats, warm_up=False)


def test_a_white_model_runs_as_before_to_the_bit(monkeypatch):
    """At (0, 0) nothing of the model is computed: the run's update uses each measurement's own
    covariance (neither the pass counter nor the inflation is called), so it is the run of the
    code before the setting."""
    import slam.loop
    from slam.history import RunHistory

    def never(*args, **kwargs):
        raise AssertionError("the pass-offset model was computed at (0, 0)")

    monkeypatch.setattr(slam.loop, "pass_inflation", never)
    monkeypatch.setattr(RunHistory, "pass_index", never)
    seen: list = []
    run = _run((0.0, 0.0), monkeypatch=monkeypatch, seen=seen)
    assert len(seen) > 10 and np.all(np.isfinite(run.pose))
    for _, z, R in seen:  # each measurement's own covariance, as logged, to the bit
        rows = [int(np.flatnonzero((run.meas_z == zi).all(axis=1))[0]) for zi in z]
        np.testing.assert_array_equal(R, run.meas_R[rows])


@pytest.mark.parametrize("gap", [2.0, 0.1])
def test_the_update_uses_the_pass_variance_of_each_sighting(monkeypatch, gap):
    """Each update's R is the measured one plus the pass offset of the sighting's index in
    its landmark's pass: 1, 2, 3, ... while the landmark is seen every scan (0.2 s), always 1
    when the gap is shorter than a scan."""
    seen = []
    sd = (0.03, 0.05)
    log = _run(sd, gap, monkeypatch, seen)
    count: dict[int, int] = {}
    n = 0
    for ids, z, R in seen:
        k = []
        for lid in ids.tolist():
            count[lid] = count.get(lid, 0) + 1 if gap > 0.2 else 1
            k.append(count[lid])
        # the measured covariance of these measurements: the log's, matched by z
        rows = [int(np.flatnonzero((log.meas_z == zi).all(axis=1))[0]) for zi in z]
        np.testing.assert_allclose(R, pass_inflation(z, log.meas_R[rows], np.array(k), sd))
        n += len(k)
    assert n > 50
    assert max(count.values()) > 10 if gap > 0.2 else max(count.values()) == 1
    # the landmarks end less certain than under the white model
    white = _run((0.0, 0.0))
    assert np.trace(log.final_P) > np.trace(white.final_P)


def test_the_smoother_weighs_a_pass_as_one_offset_and_solves():
    sd = (0.03, 0.05)
    log = _run(sd)
    white = problem_from_log(_run((0.0, 0.0)))
    p = problem_from_log(log)
    # every landmark is seen in one pass (every scan): n = its sightings in the log
    st = log.meas_status
    sighting = np.isin(log.meas_track, log.landmark_id) & (st >= -3)
    n = {
        int(lid): int(np.count_nonzero(sighting & (log.meas_track == lid)))
        for lid in log.landmark_id
    }
    k = np.array([n[int(lid)] for lid in p.meas_landmark])
    np.testing.assert_allclose(p.meas_R[:, 0, 0], white.meas_R[:, 0, 0] + k * sd[0] ** 2)
    rng2 = p.meas_z[:, 0] ** 2
    np.testing.assert_allclose(p.meas_R[:, 1, 1], white.meas_R[:, 1, 1] + k * sd[1] ** 2 / rng2)
    assert max(n.values()) > 10
    res = smooth(p)
    assert np.isfinite(res.chi2) and res.landmark_xy.shape == (LANDMARKS.shape[0], 2)


def test_the_run_log_carries_the_pass_model_to_trunkslam_smooth(tmp_path):
    """The run log holds the covariances with the pass offset (all sightings count in a
    pass), so what `trunkslam smooth` and export-graph read is what the in-memory smoother
    solves."""
    from experiments.io.run_log import read_run_log, write_run_log

    log = _run((0.03, 0.05))
    problem, _ = read_run_log(write_run_log(tmp_path / "run_log.npz", log))
    np.testing.assert_array_equal(problem.meas_R, problem_from_log(log).meas_R)
    white = problem_from_log(_run((0.0, 0.0)))
    assert np.all(problem.meas_R[:, 0, 0] > white.meas_R[:, 0, 0])
