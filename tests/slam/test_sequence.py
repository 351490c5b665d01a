"""slam.Sequence: every field validated, a clear SlamError naming the problem."""

from __future__ import annotations

import math

import numpy as np
import pytest
from support import B, N, full_kwargs

from features.types import Scan
from slam import Sequence, SlamError
from slam.sequence import OPTIONAL, REQUIRED, GpsTrack, Truth, Vehicle


def test_full_sequence_is_normalised():
    seq = Sequence(**full_kwargs())
    assert seq.n_scans == N and seq.n_beams == B
    assert seq.scan_ranges.dtype == np.float64 and seq.laser_pose.dtype == np.float64
    assert seq.scan_labels.dtype == np.int64
    assert not seq.scan_ranges.flags.writeable  # frozen all the way down
    assert seq.vehicle == Vehicle("ackermann", 2.83, 0.76)
    assert seq.vehicle.to_dict() == {
        "model": "ackermann",
        "wheelbase_m": 2.83,
        "encoder_offset_m": 0.76,
    }
    np.testing.assert_array_equal(seq.laser_pose, [3.78, 0.5, 0.0])


def test_inputs_are_copied_not_shared():
    kw = full_kwargs()
    seq = Sequence(**kw)
    kw["scan_ranges"][0, 0] = -123.0
    assert seq.scan_ranges[0, 0] != -123.0
    assert kw["scan_ranges"].flags.writeable  # the caller's array is left alone


def test_vehicle_json_string_and_default_encoder_offset():
    seq = Sequence(**{**full_kwargs(), "vehicle": '{"model": "ackermann", "wheelbase_m": 1.2}'})
    assert seq.vehicle == Vehicle("ackermann", 1.2, 0.0)


def test_scan_k_is_a_features_scan():
    seq = Sequence(**full_kwargs())
    s = seq.scan(0)
    assert isinstance(s, Scan)
    assert s.stamp_s == 10.0 and s.max_range_m == 50.0
    assert s.angle_min_rad == -math.pi / 2 and s.angle_increment_rad == math.pi / 360
    assert np.isnan(s.ranges_m[2]) and s.ranges_m[0] == seq.scan_ranges[0, 0]


def test_minimal_sequence_has_none_for_optional_fields():
    kw = full_kwargs()
    seq = Sequence(**{k: kw[k] for k in (*REQUIRED, "scan_ranges")})
    assert seq.scan_max_range == math.inf and seq.scan_n_beams == B
    for name in OPTIONAL:
        if name not in ("scan_ranges", "scan_n_beams", "scan_max_range", "name"):
            assert getattr(seq, name) is None, name
    assert seq.name == "" and not seq.has_detections


def test_sequence_errors_are_value_errors():
    assert issubclass(SlamError, ValueError)


def test_detections_only_sequence():
    kw = full_kwargs()
    dets = {k: kw[k] for k in ("det_scan", "det_range", "det_bearing", "det_radius", "det_cov")}
    seq = Sequence(**{k: kw[k] for k in REQUIRED}, scan_n_beams=361, det_method="bailey", **dets)
    assert not seq.has_ranges and seq.has_detections and seq.n_beams == 361
    scan = seq.scan(1)
    assert scan.n_beams == 361 and not scan.valid.any() and scan.stamp_s == seq.scan_t[1]
    z, r, cov = seq.detections(0)
    np.testing.assert_array_equal(z, [[5.0, -0.4], [7.5, 0.3]])
    np.testing.assert_array_equal(r, [0.2, 0.3])
    assert cov.shape == (2, 2, 2)
    z, r, cov = seq.detections(1)  # a scan without detections
    assert z.shape == (0, 2) and r.shape == (0,) and cov.shape == (0, 2, 2)
    assert seq.detections(4)[0].tolist() == [[12.0, 1.2]]
    with pytest.raises(SlamError, match="scan_n_beams: needed"):
        Sequence(**{k: kw[k] for k in REQUIRED}, **dets)
    with pytest.raises(SlamError, match="raw scans .* or precomputed detections"):
        Sequence(**{k: kw[k] for k in REQUIRED})


BAD_RUNS = [
    # (changes to the valid run, words the message must contain)
    ({"scan_t": [10.0, 10.2, 10.2, 10.6, 10.8]}, ["scan_t", "strictly increasing", "scan_t[2]"]),
    ({"scan_t": [10.0, 10.2, 10.1, 10.6, 10.8]}, ["scan_t", "strictly increasing"]),
    ({"scan_t": [10.0, np.nan, 10.4, 10.6, 10.8]}, ["scan_t", "finite"]),
    ({"scan_t": np.zeros((N, 1))}, ["scan_t", "shape"]),
    ({"scan_t": []}, ["scan_t"]),
    ({"scan_ranges": np.ones((N + 1, B))}, ["scan_ranges", "N = len(scan_t) = 5"]),
    ({"scan_ranges": np.ones(N)}, ["scan_ranges", "shape"]),
    ({"scan_ranges": np.full((N, B), "x")}, ["scan_ranges", "dtype"]),
    ({"scan_angle_min": np.nan}, ["scan_angle_min", "finite"]),
    ({"scan_angle_min": "0"}, ["scan_angle_min", "number"]),
    ({"scan_angle_increment": 0.0}, ["scan_angle_increment", "> 0"]),
    ({"scan_angle_increment": -0.01}, ["scan_angle_increment", "> 0"]),
    ({"scan_angle_increment": 90.0}, ["scan_angle_increment", "degrees"]),
    ({"scan_max_range": 0.0}, ["scan_max_range", "> 0"]),
    ({"laser_pose": [3.78, 0.5]}, ["laser_pose", "(3,)"]),
    ({"laser_pose": [3.78, np.inf, 0.0]}, ["laser_pose", "finite"]),
    ({"odo_steer": None}, ["odo_steer", "together"]),
    ({"odo_t": None, "odo_speed": None}, ["odo_", "together"]),
    ({"odo_speed": np.zeros(11)}, ["odo_speed", "like odo_t"]),
    ({"odo_steer": np.full(12, 30.0)}, ["odo_steer", "degrees"]),
    ({"odo_speed": np.full(12, np.nan)}, ["odo_speed", "finite"]),
    ({"odo_t": np.arange(12)[::-1] * 0.1}, ["odo_t", "strictly increasing"]),
    ({"vehicle": {"model": "tank", "wheelbase_m": 2.0}}, ["vehicle", "model", "ackermann"]),
    ({"vehicle": {"wheelbase_m": 2.0}}, ["vehicle", "model"]),
    ({"vehicle": {"model": "ackermann"}}, ["vehicle", "wheelbase_m"]),
    ({"vehicle": {"model": "ackermann", "wheelbase_m": 0.0}}, ["wheelbase_m", "> 0"]),
    ({"vehicle": {"model": "ackermann", "wheelbase_m": -2.83}}, ["wheelbase_m", "> 0"]),
    ({"vehicle": {"model": "ackermann", "wheelbase_m": "2.83"}}, ["wheelbase_m", "number"]),
    ({"vehicle": {"model": "ackermann", "wheelbase": 2.83}}, ["vehicle", "wheelbase"]),
    ({"vehicle": "{not json"}, ["vehicle", "JSON"]),
    ({"vehicle": [1, 2]}, ["vehicle", "dict"]),
    ({"gps_xy": None}, ["gps_xy", "together"]),
    ({"gps_xy": np.zeros((3, 3))}, ["gps_xy", "(n, 2)"]),
    ({"gps_xy": np.zeros((2, 2))}, ["gps_xy", "like gps_t"]),
    ({"gps_t": [10.0, 9.0, 11.0]}, ["gps_t", "strictly increasing"]),
    ({"gps_pose": [1.0, 0.0]}, ["gps_pose", "(3,)"]),
    ({"truth_pose": None}, ["truth_pose", "together"]),
    ({"truth_pose": np.zeros((N, 2))}, ["truth_pose", "(n, 3)"]),
    ({"truth_pose": np.zeros((N - 1, 3))}, ["truth_pose", "like truth_t"]),
    ({"truth_t": np.arange(N)[::-1] * 1.0}, ["truth_t", "strictly increasing"]),
    ({"truth_landmarks": np.array([[1.0, 2.0, 0.0]])}, ["truth_landmarks", "r must be > 0"]),
    ({"truth_landmarks": np.array([[1.0, 2.0, -0.3]])}, ["truth_landmarks", "row 0"]),
    ({"truth_landmarks": np.zeros((2, 2))}, ["truth_landmarks", "(n, 3)"]),
    ({"scan_labels": np.zeros((N, B + 1), int)}, ["scan_labels", "like scan_ranges"]),
    ({"scan_labels": np.zeros((N, B))}, ["scan_labels", "integers"]),
    ({"scan_labels": np.full((N, B), -3)}, ["scan_labels", ">= -2"]),
    ({"name": 5}, ["name", "string"]),
    ({"scan_n_beams": B + 1}, ["scan_n_beams", f"{B + 1} but scan_ranges has {B}"]),
    ({"scan_n_beams": 2.5}, ["scan_n_beams", "whole number"]),
    ({"det_scan": [0, 2, 0, 4]}, ["det_scan", "sorted"]),
    ({"det_scan": [0, 0, 2, N]}, ["det_scan", f"0..{N - 1}"]),
    ({"det_scan": [0.0, 0.0, 2.0, 4.0]}, ["det_scan", "integers"]),
    ({"det_range": [5.0, -1.0, 6.2, 12.0]}, ["det_range", "> 0"]),
    ({"det_range": [5.0, 7.5, 6.2]}, ["det_range", "(4,) like det_scan"]),
    ({"det_bearing": [0.0, np.nan, 0.0, 0.0]}, ["det_bearing", "finite"]),
    ({"det_radius": [0.2, -0.3, 0.1, 0.1]}, ["det_radius", ">= 0"]),
    ({"det_radius": None}, ["det_radius", "missing"]),
    ({"det_cov": np.array([np.diag([0.01, -1e-4])] * 4)}, ["det_cov", "positive definite"]),
    ({"det_cov": np.zeros((3, 2, 2))}, ["det_cov", "(4, 2, 2)"]),
    ({"det_method": ""}, ["det_method", "non-empty"]),
]


@pytest.mark.parametrize("changes, words", BAD_RUNS)
def test_malformed_run_raises_naming_the_problem(changes, words):
    kw = {**full_kwargs(), **changes}
    with pytest.raises(SlamError) as info:
        Sequence(**kw)
    msg = str(info.value)
    for w in words:
        assert w in msg, f"{w!r} not in {msg!r}"


@pytest.mark.parametrize(
    "changes, name",
    [
        ({"odo_t": [], "odo_speed": [], "odo_steer": []}, "odo_t"),
        ({"gps_t": [], "gps_xy": np.zeros((0, 2))}, "gps_t"),
        ({"truth_t": [], "truth_pose": np.zeros((0, 3))}, "truth_t"),
    ],
)
def test_an_empty_optional_group_is_refused(changes, name):
    with pytest.raises(SlamError, match=f"Sequence.{name}: empty"):
        Sequence(**{**full_kwargs(), **changes})


def test_sub_records_name_the_flat_fields():
    seq = Sequence(**full_kwargs())
    assert seq.odometry.t_s is seq.odo_t and seq.odometry.steer_rad is seq.odo_steer
    assert isinstance(seq.gps, GpsTrack) and seq.gps.xy_m is seq.gps_xy
    assert isinstance(seq.truth, Truth) and seq.truth.pose_world_rear_axle is seq.truth_pose
    bare = {k: v for k, v in full_kwargs().items() if not k.startswith(("odo_", "gps_", "truth"))}
    seq = Sequence(**bare)
    assert seq.odometry is None and seq.gps is None and seq.truth is None


def test_the_vehicle_is_a_type_read_from_a_dict_or_json():
    v = Vehicle.of('{"model": "ackermann", "wheelbase_m": 2.0}')
    assert v == Vehicle("ackermann", 2.0, 0.0) and Vehicle.of(v) is v
    assert Vehicle.of(v.to_dict()) == v
    with pytest.raises(SlamError, match="unknown or missing 'model'"):
        Vehicle.of({"model": "tank", "wheelbase_m": 2.0})
    with pytest.raises(SlamError, match=r"vehicle\['wheelbase_m'\]: must be > 0"):
        Vehicle.of({"model": "ackermann", "wheelbase_m": -1.0})
