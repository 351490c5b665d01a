"""The Victoria Park reader against the facts verified in its README (shared/datasets)."""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import pytest

import experiments.io.paths as data
from experiments.errors import ConfigError, DataError
from experiments.io.sequence_file import load_sequence, save_sequence
from experiments.io.victoria_park import (
    VP_FILES,
    load_raw_sick_ranges,
    load_raw_sick_words,
    load_reference_detections,
    load_victoria_park,
)


@pytest.fixture(scope="module")
def vp(vp_dir):
    return load_victoria_park(vp_dir)


# ---- the run ---------------------------------------------------------------------------------


@pytest.mark.data
def test_scans(vp):
    assert vp.name == "victoria_park"
    assert vp.scan_ranges.shape == (2000, 361) and vp.n_scans == 2000
    assert vp.scan_t[0] == pytest.approx(21.819, abs=1e-9)
    assert vp.scan_t[-1] == pytest.approx(448.865, abs=1e-9)
    steps = np.diff(vp.scan_t)
    assert steps.min() >= 0.212 and steps.max() <= 0.216  # 213-215 ms, about 4.67 Hz
    assert vp.scan_angle_min == -math.pi / 2
    assert vp.scan_angle_increment == math.pi / 360
    assert vp.scan_max_range == 80.0
    np.testing.assert_array_equal(vp.laser_pose, [3.78, 0.50, 0.0])
    np.testing.assert_array_equal(vp.gps_pose, [3.78, 0.50, 0.0])
    assert vp.vehicle.to_dict() == {
        "model": "ackermann",
        "wheelbase_m": 2.83,
        "encoder_offset_m": 0.76,
    }
    assert vp.truth_t is None and vp.truth_landmarks is None and vp.scan_labels is None


@pytest.mark.data
def test_scan_ranges_decode_the_13_bit_words(vp, vp_dir):
    r = vp.scan_ranges
    valid = np.isfinite(r)
    assert np.mean(~valid) == pytest.approx(0.829, abs=0.001)  # 82.9 % no return
    assert r[valid].min() == pytest.approx(0.07)  # 7 cm
    assert r[valid].max() < 80.0
    words = load_raw_sick_words(vp_dir)
    assert words.dtype == np.uint16 and words.shape == (2000, 361)
    assert int(np.count_nonzero(words > 8191)) == 4  # the only words with intensity bits
    masked = load_raw_sick_ranges(vp_dir, no_return_as_nan=False)
    assert masked.max() == pytest.approx(81.91)
    np.testing.assert_array_equal(r[valid], masked[valid])
    np.testing.assert_array_equal(~valid, masked >= 80.0)
    # Scan k of the run is row k of sick.mat, as a features.Scan with beam 0 at -pi/2.
    s = vp.scan(7)
    assert s.stamp_s == vp.scan_t[7] and s.angle_min_rad == -math.pi / 2
    np.testing.assert_array_equal(s.ranges_m, r[7])


@pytest.mark.data
def test_odometry(vp):
    assert vp.odo_t.shape == vp.odo_speed.shape == vp.odo_steer.shape == (61945,)
    assert vp.odo_t[0] == pytest.approx(21.940) and vp.odo_t[-1] == pytest.approx(1570.540)
    np.testing.assert_allclose(np.diff(vp.odo_t), 0.025, atol=1e-9)  # 40 Hz
    assert vp.odo_speed.min() == pytest.approx(-0.059, abs=5e-4)
    assert vp.odo_speed.max() == pytest.approx(6.628, abs=5e-4)
    assert vp.odo_speed.mean() == pytest.approx(2.60, abs=0.005)
    assert vp.odo_steer.min() == pytest.approx(-0.592, abs=5e-4)
    assert vp.odo_steer.max() == pytest.approx(0.564, abs=5e-4)
    distance_m = float(np.sum(vp.odo_speed[:-1] * np.diff(vp.odo_t)))
    assert distance_m == pytest.approx(4030, abs=5)


@pytest.mark.data
def test_gps(vp):
    assert vp.gps_t.shape == (4466,) and vp.gps_xy.shape == (4466, 2)
    assert vp.gps_t[0] == pytest.approx(20.967) and vp.gps_t[-1] == pytest.approx(1570.193)
    x, y = vp.gps_xy[:, 0], vp.gps_xy[:, 1]  # x = Lo_m (east), y = La_m (north)
    assert x.min() == pytest.approx(-254.14, abs=0.005)
    assert x.max() == pytest.approx(55.16, abs=0.005)
    assert y.min() == pytest.approx(-79.98, abs=0.005)
    assert y.max() == pytest.approx(176.18, abs=0.005)
    gaps = np.diff(vp.gps_t)
    assert int(np.count_nonzero(gaps > 2.0)) == 67  # the failing receiver
    assert gaps.max() == pytest.approx(58.3, abs=0.05)


@pytest.mark.data
def test_first_n_scans(vp_dir, vp):
    short = load_victoria_park(vp_dir, n_scans=10)
    assert short.n_scans == 10
    np.testing.assert_array_equal(short.scan_ranges, vp.scan_ranges[:10])
    np.testing.assert_array_equal(short.scan_t, vp.scan_t[:10])
    assert short.odo_t.shape == (61945,)  # odometry and GPS are always complete
    for bad in (0, 2001, 2.5, True):
        with pytest.raises(ValueError, match="n_scans"):
            load_victoria_park(vp_dir, n_scans=bad)


@pytest.mark.data
def test_reference_detections(vp_dir, vp):
    t_s, zt = load_reference_detections(vp_dir)
    assert t_s.shape == (7249,) and len(zt) == 7249
    assert t_s[0] == pytest.approx(21.819) and t_s[-1] == pytest.approx(1570.208)
    np.testing.assert_array_equal(t_s[:2000], vp.scan_t)
    counts = np.array([z.shape[1] for z in zt])
    assert all(z.shape[0] == 3 and z.dtype == np.float64 for z in zt)
    assert counts.sum() == 52974 and counts.max() == 18 and np.count_nonzero(counts == 0) == 19
    allz = np.concatenate(zt, axis=1)
    assert allz[0].min() == pytest.approx(1.48, abs=0.005)
    assert allz[0].max() == pytest.approx(75.3, abs=0.05)
    assert 0.11 < allz[1].min() and allz[1].max() < 3.09  # bearings 0..pi
    assert np.median(allz[2]) == pytest.approx(0.42, abs=0.005)


@pytest.mark.data
def test_round_trip_through_a_sequence_file(vp, tmp_path):
    back = load_sequence(save_sequence(vp, tmp_path / "vp.npz"))
    for name in ("scan_t", "scan_ranges", "odo_t", "odo_speed", "odo_steer", "gps_t", "gps_xy"):
        np.testing.assert_array_equal(getattr(back, name), getattr(vp, name), err_msg=name)
    assert back.vehicle == vp.vehicle and back.scan_max_range == 80.0
    assert back.scan_angle_increment == math.pi / 360 and back.name == "victoria_park"


# ---- missing or broken data ------------------------------------------------------------------


def _partial_copy(vp_dir: Path, dest: Path, skip: str) -> Path:
    """Symlink every reader file except `skip` into dest."""
    for key, rel in VP_FILES.items():
        if key == skip:
            continue
        (dest / rel).parent.mkdir(parents=True, exist_ok=True)
        os.symlink(vp_dir / rel, dest / rel)
    return dest


@pytest.mark.data
@pytest.mark.parametrize("skip", sorted(VP_FILES))
def test_missing_file_is_named_with_where_to_get_it(vp_dir, tmp_path, skip):
    root = _partial_copy(vp_dir, tmp_path, skip)
    with pytest.raises(DataError) as info:
        load_victoria_park(root)
    msg = str(info.value)
    assert VP_FILES[skip] in msg and "README.md" in msg


def test_corrupt_mat_file(tmp_path, monkeypatch):
    import experiments.io.victoria_park as vp

    (tmp_path / "partial_raw_scans_ss2002").mkdir()
    (tmp_path / VP_FILES["sick"]).write_bytes(b"MATLAB 5.0 MAT-file, garbage" + bytes(200))
    with pytest.raises(DataError, match="sick.mat: sha256 .* differs"):  # caught by its sum
        load_raw_sick_ranges(tmp_path)
    monkeypatch.setattr(vp, "VP_SHA256", {})  # no sum to check: the reader's own error
    with pytest.raises(DataError, match="cannot be read as a MATLAB file"):
        load_raw_sick_ranges(tmp_path)


def test_mat_file_without_the_variable(tmp_path, monkeypatch):
    from scipy.io import savemat

    import experiments.io.victoria_park as vp

    monkeypatch.setattr(vp, "VP_SHA256", {})  # a hand-made file has no published sum

    savemat(tmp_path / "aa3_dr.mat", {"time": np.arange(3), "speed": np.zeros(3)})
    from experiments.io.victoria_park import load_mat

    with pytest.raises(DataError, match=r"missing variable\(s\) \['steering'\]"):
        load_mat(tmp_path, "odometry", ("time", "speed", "steering"))


def test_data_root_from_the_environment(tmp_path, monkeypatch):
    monkeypatch.setenv(data.DATA_ENV, str(tmp_path))
    assert data.data_root() == tmp_path.resolve()
    with pytest.raises(DataError, match="Victoria Park folder not found"):
        data.victoria_park_dir()
    (tmp_path / "victoria_park").mkdir()
    assert data.victoria_park_dir() == tmp_path.resolve() / "victoria_park"


def test_relative_data_root_is_taken_from_the_current_folder(tmp_path, monkeypatch):
    (tmp_path / "d").mkdir()
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv(data.DATA_ENV, "d")
    assert data.data_root() == (tmp_path / "d").resolve()


def test_data_root_that_does_not_exist(tmp_path, monkeypatch):
    monkeypatch.setenv(data.DATA_ENV, str(tmp_path / "nowhere"))
    with pytest.raises(DataError) as info:
        data.data_root()
    assert "nowhere" in str(info.value) and "README.md" in str(info.value)


def test_no_environment_and_no_default_folder(tmp_path, monkeypatch):
    monkeypatch.delenv(data.DATA_ENV, raising=False)
    monkeypatch.setattr(data, "DEFAULT_DATA_ROOT", tmp_path / "missing")
    with pytest.raises(DataError) as info:
        data.data_root()
    msg = str(info.value)
    assert data.DATA_ENV in msg and "missing" in msg and "README.md" in msg


def test_default_folder_when_the_environment_is_unset(tmp_path, monkeypatch):
    # The real default is ../shared/datasets beside the repository.
    assert data.DEFAULT_DATA_ROOT == data.REPO_ROOT.parent / "shared" / "datasets"
    monkeypatch.delenv(data.DATA_ENV, raising=False)
    monkeypatch.setattr(data, "DEFAULT_DATA_ROOT", tmp_path)
    assert data.data_root() == tmp_path.resolve()


def test_full_run_loader(vp_dir):
    from experiments.io.victoria_park import load_victoria_park

    seq = load_victoria_park(vp_dir, full=True)
    assert seq.n_scans == 7249 and not seq.has_ranges and seq.n_beams == 361
    assert seq.det_scan.size == 52974 and seq.det_method == "bailey"
    assert np.all(np.abs(seq.det_bearing) <= np.pi / 2)
    raw = load_victoria_park(vp_dir, n_scans=10)
    assert raw.has_ranges and raw.has_detections
    z, r, cov = raw.detections(0)
    _, dets = load_reference_detections(vp_dir)
    np.testing.assert_allclose(z[:, 0], dets[0][0])
    np.testing.assert_allclose(z[:, 1], dets[0][1] - np.pi / 2)
    np.testing.assert_allclose(r, dets[0][2] / 2)
    assert cov is None


@pytest.mark.slow
def test_first_1000_scans_match_the_golden_figures(vp_dir):
    """Landmarks within 5 of the golden count, GPS RMSE and NIS within 10%: the run depends on
    the LP solver and BLAS rounding through the association, not on randomness."""
    import json

    from regenerate_golden import FILES, victoria_park_1000

    gold = json.loads(FILES["victoria_park"].read_text())
    got = victoria_park_1000()
    assert abs(got["landmarks"] - gold["landmarks"]) <= 5
    assert got["fixes"] == gold["fixes"] and got["jumps"] == gold["jumps"]
    for k in ("rmse_m", "median_m", "rmse_aligned_m", "nis_inside"):
        assert got[k] == pytest.approx(gold[k], rel=0.10), k


def test_ss2002_reference_is_read(vp_dir):
    from experiments.io.victoria_park import load_ss2002_reference

    ground, trees = load_ss2002_reference(vp_dir)
    assert ground.shape == (2000, 3) and trees.shape == (145, 3)
    np.testing.assert_allclose(ground[0], 0.0, atol=1e-12)
    assert 0.05 < np.median(trees[:, 2]) < 0.5


# ---- the preset's consistency step (experiments/paper/victoria_park/calibration.py) ----------


def test_scale_measurement_noise_scales_every_sigma_and_rejects_bad_factors():
    from experiments.io.config_file import load_slam_config, preset_path
    from experiments.paper.victoria_park.calibration import scale_measurement_noise

    cfg = load_slam_config(preset_path("victoria_park_ute"))
    half = scale_measurement_noise(cfg, 0.5)
    assert set(half.measurement.constant_noise) == set(cfg.measurement.constant_noise)
    for name, m in cfg.measurement.constant_noise.items():
        h = half.measurement.constant_noise[name]
        assert h.range_sigma_m == 0.5 * m.range_sigma_m
        assert h.range_sigma_per_m == 0.5 * m.range_sigma_per_m
        assert h.bearing_sigma_rad == 0.5 * m.bearing_sigma_rad
    assert half.vehicle.odometry_noise == cfg.vehicle.odometry_noise
    assert half.vehicle.laser_pose == cfg.vehicle.laser_pose
    for bad in (0.0, -1.0, math.nan, math.inf):
        with pytest.raises(ConfigError, match="k: the noise factor"):
            scale_measurement_noise(cfg, bad)


@pytest.mark.slow
@pytest.mark.data
def test_consistency_scale_brings_nis_per_dof_to_one(vp_dir):
    """On the first 300 scans: NIS per dof falls as the measurement sigmas grow, the bisection
    lands within 5% of 1 from a bracket that holds the crossing and from one that must be
    widened, and a bracket that cannot reach it is an error naming it."""
    from experiments.io.config_file import load_slam_config, preset_path
    from experiments.paper.victoria_park.calibration import consistency_scale

    seq = load_victoria_park(vp_dir, n_scans=300)
    # the step the calibration makes before it derives the pass offset: white errors
    cfg = load_slam_config(preset_path("victoria_park_ute")).with_(
        **{"measurement.pass_offset_sd_m": [0.0, 0.0]}
    )
    got = consistency_scale(seq, cfg, bracket=(0.5, 2.0), iterations=5)
    ks, v = np.array(got["evaluations"]).T
    order = np.argsort(ks)
    assert np.all(np.diff(v[order]) < 0)  # monotone over the evaluated factors
    assert got["nis_per_dof"] == pytest.approx(1.0, abs=0.05)
    assert 0.5 < got["k"] < 2.0
    wide = consistency_scale(seq, cfg, bracket=(3.0, 4.0), iterations=5)
    assert wide["evaluations"][2][0] == 1.5  # widened downwards: 3 -> 1.5 (-> 0.75 ...)
    assert wide["nis_per_dof"] == pytest.approx(1.0, abs=0.05)
    with pytest.raises(ConfigError, match="bracket: NIS per dof is"):
        consistency_scale(seq, cfg, bracket=(60.0, 70.0), iterations=1)
    with pytest.raises(ConfigError, match="bracket: expected 0 < low < high"):
        consistency_scale(seq, cfg, bracket=(2.0, 1.0))


def test_calibration_parameters_with_and_without_the_motion_terms():
    from experiments.paper.victoria_park.calibration import START, config_from

    plain = config_from(START[:6]).vehicle.odometry_noise
    assert plain.speed_sigma_per_speed == 0 and plain.steer_sigma_per_lateral_mps2 == 0
    grown = config_from(START).vehicle.odometry_noise
    assert grown.speed_sigma_per_speed == pytest.approx(0.05)
    assert grown.steer_sigma_per_lateral_mps2 == pytest.approx(0.05)
    assert grown.speed_sigma_mps == plain.speed_sigma_mps == pytest.approx(0.5)
    with pytest.raises(ConfigError, match="theta: expected 6 or 8 parameters, got 7"):
        config_from(START[:7])
    from experiments.paper.victoria_park.calibration import calibrate

    with pytest.raises(ConfigError, match=r"start: expected 8 parameters, got \(6,\)"):
        calibrate(None, motion_terms=True, start=START[:6])  # checked before any run


def test_the_motion_terms_must_buy_more_likelihood_than_they_cost():
    """BIC = 2 J + p ln(n): with 10,000 measurements two more parameters cost 18.4 in 2 J, so
    the 8-parameter fit is chosen only when its J is lower by more than 9.2."""
    from experiments.paper.victoria_park.calibration import bic, select_model

    constant = {"J": -1000.0, "theta": [0.0] * 6, "measurements": 10_000}
    assert bic(constant) == pytest.approx(-2000.0 + 6 * math.log(10_000))
    for gain, chosen in ((9.0, False), (9.5, True), (2816.0, True)):
        motion = {"J": -1000.0 - gain, "theta": [0.0] * 8, "measurements": 10_000}
        assert select_model(constant, motion) is chosen


def test_calibration_writes_what_the_preset_holds():
    """The calibration's fixed settings (BASE), its parameter vector (the motion-dependent
    model, the one its BIC chose), steering calibration, laser latency, start stretch,
    confirm_scans and range bias rebuild the shipped preset exactly, so `reproduce
    victoria-park-calibration` writes the preset's settings."""
    from experiments.io.config_file import load_slam_config, preset_path
    from experiments.paper.victoria_park.calibration import preset_config

    preset = load_slam_config(preset_path("victoria_park_ute"))
    m = preset.measurement.constant_noise["bailey"]
    odometry = preset.vehicle.odometry_noise
    theta = [
        preset.vehicle.laser_pose[2],
        *np.log(
            [
                odometry.speed_sigma_mps,
                odometry.steer_sigma_rad,
                m.range_sigma_m,
                m.range_sigma_per_m,
                m.bearing_sigma_rad,
                odometry.speed_sigma_per_speed,
                odometry.steer_sigma_per_lateral_mps2,
            ]
        ),
    ]
    assert preset.start.gps_track == "slam" and not preset.vehicle.steering.is_identity
    got = preset_config(
        theta,
        preset.vehicle.steering,
        preset.start.gps_fit_m,
        preset.map_policy.confirm_scans,
        latency_s=preset.vehicle.laser_latency_s,
        pass_offset_sd_m=preset.measurement.pass_offset_sd_m,
        range_bias=preset.measurement.range_bias["bailey"],
    ).to_dict()
    want = preset.to_dict()

    def flat(d, pre=""):
        for k, v in d.items():
            if isinstance(v, dict):
                yield from flat(v, f"{pre}{k}.")
            else:
                yield f"{pre}{k}", v

    got, want = dict(flat(got)), dict(flat(want))
    assert got.keys() == want.keys()
    for k, v in want.items():
        if isinstance(v, float) or (isinstance(v, list) and v and isinstance(v[0], float)):
            np.testing.assert_allclose(got[k], v, rtol=1e-12, err_msg=k)
        else:
            assert got[k] == v, k


def test_start_stretch_is_the_shortest_from_which_the_heading_holds():
    """`vp_start.derive`: the shortest D from which every longer fit is within the tolerance
    of the whole path's heading, even when a shorter one came close before."""
    from experiments.paper.victoria_park.start import derive

    rows = [(50.0, 36.9, 10), (100.0, 35.0, 20), (150.0, 36.6, 30), (200.0, 36.8, 40)]
    assert derive(rows, 0.3) == 150.0
    assert derive(rows, 0.1) == 200.0
    assert derive(rows, 2.0) == 50.0
    assert derive([(300.0, 35.0, 9)]) == 300.0


@pytest.mark.slow
@pytest.mark.data
def test_the_preset_start_stretch_follows_its_rule_on_scans_1_2000(vp_dir):
    """The preset's gps_start_fit_m is what `vp_start` derives on scans 1-2000 with the
    preset's noise and, as the calibration derives the start before the map policy, the
    paper's confirm_scans; the start headings of fits longer than it agree within the
    tolerance."""
    from experiments.io.config_file import load_slam_config, preset_path
    from experiments.paper.victoria_park import start as vp_start
    from experiments.paper.victoria_park.calibration import BASE

    cfg = load_slam_config(preset_path("victoria_park_ute"))
    at_start = cfg.with_(  # and before the pass offset: white errors
        **{
            "map_policy.confirm_scans": BASE.map_policy.confirm_scans,
            "measurement.pass_offset_sd_m": [0.0, 0.0],
        }
    )
    rows = vp_start.headings(load_victoria_park(vp_dir, n_scans=2000), at_start)
    assert vp_start.derive(rows) == cfg.start.gps_fit_m
    later = [h for d, h, _ in rows if d >= cfg.start.gps_fit_m]
    assert max(later) - min(later) <= 2 * vp_start.TOLERANCE_DEG
    assert rows[-1][0] > 900  # scans 1-2000 drive about a kilometre


@pytest.mark.slow
@pytest.mark.data
def test_the_preset_range_bias_is_the_trace_fixed_point_on_scans_1_2000(vp_dir):
    """The preset's range bias of the published detections is what the calibration's step
    (`derive_range_bias`) derives on scans 1-2000 from the preset's other settings: three runs,
    the last one's trace fit within the tolerance, the first one's range error the largest."""
    from experiments.io.config_file import load_slam_config, preset_path
    from experiments.paper.victoria_park.calibration import RANGE_BIAS_RUNS, derive_range_bias

    cfg = load_slam_config(preset_path("victoria_park_ute"))
    want = cfg.measurement.range_bias["bailey"]
    assert want[0] > 0.03 and want[1] < -0.001  # centres too far near the ute, too near far out
    before = cfg.with_(**{"measurement.range_bias": {"bailey": (0.0, 0.0)}})
    got, fits = derive_range_bias(load_victoria_park(vp_dir, n_scans=2000), before, RANGE_BIAS_RUNS)
    np.testing.assert_allclose(got, want, rtol=1e-9)
    assert len(fits) == 3  # the runs of the fixed point (the notebook's derivation)
    first, last = fits[0][1], fits[-1][1]
    assert abs(last.range_offset_m) < 0.002 and abs(last.range_scale) < 2e-4
    assert abs(first.range_offset_m) > 10 * abs(last.range_offset_m) and first.passes > 200


@pytest.mark.slow
@pytest.mark.data
def test_the_pass_offset_criterion_sees_correlated_error_on_scans_1_2000(vp_dir):
    """The leave-one-pass-out derivation (`vp_pass_offset.derive`) on scans 1-2000 with the
    preset's settings: the white model's median statistic is far above the chi-square(1)
    median on both axes, and the derived s brings each to it. The preset does not adopt it
    (calibration module doc): it keeps white errors."""
    from experiments.eval.pass_offsets import CHI2_1_MEDIAN
    from experiments.io.config_file import load_slam_config, preset_path
    from experiments.paper.victoria_park import pass_offset as vp_pass_offset

    cfg = load_slam_config(preset_path("victoria_park_ute"))
    assert cfg.measurement.pass_offset_sd_m == (0.0, 0.0)
    po = vp_pass_offset.derive(load_victoria_park(vp_dir, n_scans=2000), cfg)
    np.testing.assert_allclose(po.median_derived, CHI2_1_MEDIAN, atol=1e-3)
    assert min(po.median_white) > 4 * CHI2_1_MEDIAN and po.landmarks > 50
    assert 0.02 < min(po.sd_m) and max(po.sd_m) < 0.1
    # the drift (experiments.eval.pass_drift) from the same run: its between-pass sill, a
    # second criterion on other pairs of sightings, gives the same s within 25% across the line
    # of sight. Along it the two agreed within 25% at latency 0 and parted when the preset
    # gained its laser latency (sill 0.072 m against 0.040 m; lab notebook, the calibration
    # re-run): there both see a correlated error, the sill more
    d = po.drift
    assert d.bins >= 10 and 0 < d.corr_rad < math.inf
    np.testing.assert_allclose(d.sd_between_m[1], po.sd_m[1], rtol=0.25)
    assert d.sd_between_m[0] > po.sd_m[0] > 0.02


# ---- the laser latency (experiments/paper/victoria_park/calibration.py) ----------------------


def test_derive_latency_is_the_vertex_of_the_profiles_parabola_inside_the_grid():
    from experiments.paper.victoria_park.calibration import LATENCIES_S, derive_latency

    def J(lat, best):
        return -61000.0 + 1e5 * (lat - best) ** 2

    for best in (0.055, 0.0, 0.071):
        assert derive_latency([(x, J(x, best)) for x in LATENCIES_S]) == pytest.approx(best)
    # the vertex beyond the grid: the grid's end (the grid should be widened)
    assert derive_latency([(x, J(x, 0.3)) for x in LATENCIES_S]) == LATENCIES_S[-1]
    assert derive_latency([(x, J(x, -0.3)) for x in LATENCIES_S]) == LATENCIES_S[0]
    # an uneven grid: still the vertex
    grid = (0.0, 0.01, 0.05, 0.06, 0.1)
    assert derive_latency([(x, J(x, 0.052)) for x in grid]) == pytest.approx(0.052)
    # bumps of +-40 at the grid's scale (associations flipping) do not move it to a bump: the
    # lowest J is at 20 ms, the profile's vertex stays within 10 ms of the true 60 ms
    bumps = [0.0, 40.0, -40.0, 40.0, -40.0, 40.0, 0.0, -40.0, 40.0]
    bumpy = [(x, J(x, 0.06) + d) for x, d in zip(LATENCIES_S, bumps, strict=True)]
    bumpy[3] = (bumpy[3][0], min(j for _, j in bumpy) - 1.0)
    assert abs(derive_latency(bumpy) - 0.06) < 0.01
    # a profile that does not curve upwards: its lowest J
    assert derive_latency([(x, -x) for x in LATENCIES_S]) == LATENCIES_S[-1]
    for bad in ([], [(0.02, 1.0), (0.0, 2.0)], [(0.0, 1.0), (0.02, math.nan)]):
        with pytest.raises(ConfigError, match="latency profile"):
            derive_latency(bad)


@pytest.mark.slow
@pytest.mark.data
def test_latency_profile_is_j_at_each_latency_and_zero_is_the_plain_run(vp_dir):
    """On the first 200 scans: the profile's J at 0 is the calibration's J without the
    setting, to the bit; at 60 ms it differs (each scan is placed at another pose)."""
    from experiments.io.config_file import load_slam_config, preset_path
    from experiments.paper.victoria_park.calibration import BASE, START, latency_profile, objective

    seq = load_victoria_park(vp_dir, n_scans=200)
    steering = load_slam_config(preset_path("victoria_park_ute")).vehicle.steering
    base = BASE.with_(**{"vehicle.steering": steering})
    rows = latency_profile(seq, START[:6], base, (0.0, 0.06))
    assert [lat for lat, _ in rows] == [0.0, 0.06]
    assert rows[0][1] == objective(seq, START[:6], base)[0]
    assert rows[1][1] != rows[0][1] and math.isfinite(rows[1][1])


def test_an_installed_wheel_names_no_repository_and_no_default(tmp_path, monkeypatch):
    """From a wheel there is no repository beside the package: the message says where the data
    come from without pointing to one, and no default folder is tried."""
    monkeypatch.delenv(data.DATA_ENV, raising=False)
    monkeypatch.setattr(data, "DEFAULT_DATA_ROOT", tmp_path)  # exists, but not for a wheel
    monkeypatch.setattr(data, "IN_CHECKOUT", False)
    with pytest.raises(DataError) as info:
        data.data_root()
    msg = str(info.value)
    assert "beside" not in msg and "repository" not in msg and str(tmp_path) not in msg
    assert data.DATA_ENV in msg and "aa3_dr.mat" in msg and "README" in msg
    monkeypatch.setattr(data, "IN_CHECKOUT", True)
    assert data.data_root() == tmp_path.resolve()
