"""The sequence file: round trips, and a clear DataError for every malformed run or file."""

from __future__ import annotations

import json
import logging
import math
import os
import zipfile

import numpy as np
import pytest

from experiments.errors import DataError, TrunkslamError
from experiments.sequence import OPTIONAL, REQUIRED, Sequence, load_sequence, save_sequence
from features.types import Scan

N, B = 5, 7


def full_kwargs() -> dict:
    """Every field of a small simulated-looking run, all valid."""
    rng = np.random.default_rng(1)
    ranges = rng.uniform(1.0, 30.0, (N, B))
    ranges[0, 2] = np.nan
    ranges[3, :] = np.nan  # a scan with no return at all
    labels = rng.integers(-1, 6, (N, B))
    labels[1, 1] = -2  # mixed return
    return dict(
        scan_t=np.arange(N) * 0.2 + 10.0,
        scan_ranges=ranges,
        scan_angle_min=-math.pi / 2,
        scan_angle_increment=math.pi / 360,
        laser_pose=[3.78, 0.5, 0.0],
        scan_max_range=50.0,
        odo_t=np.arange(12) * 0.1 + 10.0,
        odo_speed=np.linspace(0.0, 2.0, 12),
        odo_steer=np.linspace(-0.1, 0.1, 12),
        vehicle={"model": "ackermann", "wheelbase_m": 2.83, "encoder_offset_m": 0.76},
        gps_t=np.array([10.0, 10.5, 11.0]),
        gps_xy=np.array([[0.0, 1.0], [1.0, 1.5], [2.0, 2.0]]),
        gps_pose=[1.0, 0.0, 0.0],
        truth_t=np.arange(N) * 0.2 + 10.0,
        truth_pose=rng.normal(size=(N, 3)),
        truth_landmarks=np.array([[5.0, 1.0, 0.2], [8.0, -2.0, 0.35]]),
        scan_labels=labels,
        name="unit test run",
    )


def assert_same(a: Sequence, b: Sequence) -> None:
    for name in (*REQUIRED, *OPTIONAL):
        va, vb = getattr(a, name), getattr(b, name)
        if isinstance(va, np.ndarray):
            assert isinstance(vb, np.ndarray), name
            assert va.dtype == vb.dtype and va.shape == vb.shape, name
            np.testing.assert_array_equal(va, vb, err_msg=name)  # NaN == NaN here
        else:
            assert va == vb, name


# ---- in memory --------------------------------------------------------------------------------


def test_full_sequence_is_normalised():
    seq = Sequence(**full_kwargs())
    assert seq.n_scans == N and seq.n_beams == B
    assert seq.scan_ranges.dtype == np.float64 and seq.laser_pose.dtype == np.float64
    assert seq.scan_labels.dtype == np.int64
    assert not seq.scan_ranges.flags.writeable  # frozen all the way down
    assert seq.vehicle == {"model": "ackermann", "wheelbase_m": 2.83, "encoder_offset_m": 0.76}
    np.testing.assert_array_equal(seq.laser_pose, [3.78, 0.5, 0.0])


def test_inputs_are_copied_not_shared():
    kw = full_kwargs()
    seq = Sequence(**kw)
    kw["scan_ranges"][0, 0] = -123.0
    assert seq.scan_ranges[0, 0] != -123.0
    assert kw["scan_ranges"].flags.writeable  # the caller's array is left alone


def test_vehicle_json_string_and_default_encoder_offset():
    seq = Sequence(**{**full_kwargs(), "vehicle": '{"model": "ackermann", "wheelbase_m": 1.2}'})
    assert seq.vehicle == {"model": "ackermann", "wheelbase_m": 1.2, "encoder_offset_m": 0.0}


def test_scan_k_is_a_features_scan():
    seq = Sequence(**full_kwargs())
    s = seq.scan(0)
    assert isinstance(s, Scan)
    assert s.stamp_s == 10.0 and s.max_range_m == 50.0
    assert s.angle_min_rad == -math.pi / 2 and s.angle_increment_rad == math.pi / 360
    assert np.isnan(s.ranges_m[2]) and s.ranges_m[0] == seq.scan_ranges[0, 0]


def test_minimal_sequence_has_none_for_optional_fields():
    kw = full_kwargs()
    seq = Sequence(**{k: kw[k] for k in REQUIRED})
    assert seq.scan_max_range == math.inf
    for name in OPTIONAL:
        if name not in ("scan_max_range", "name"):
            assert getattr(seq, name) is None, name
    assert seq.name == ""


def test_data_error_is_a_value_error():
    assert issubclass(DataError, ValueError) and issubclass(DataError, TrunkslamError)


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
]


@pytest.mark.parametrize("changes, words", BAD_RUNS)
def test_malformed_run_raises_data_error_naming_the_problem(changes, words):
    kw = {**full_kwargs(), **changes}
    with pytest.raises(DataError) as info:
        Sequence(**kw)
    msg = str(info.value)
    for w in words:
        assert w in msg, f"{w!r} not in {msg!r}"


# ---- files -----------------------------------------------------------------------------------


def test_round_trip_every_field(tmp_path):
    seq = Sequence(**full_kwargs())
    path = save_sequence(seq, tmp_path / "run.npz")
    assert path == tmp_path / "run.npz" and path.is_file()
    back = load_sequence(path)
    assert_same(seq, back)
    assert back.vehicle == seq.vehicle and back.name == "unit test run"
    # The file holds plain arrays only: it loads without pickle, vehicle is a JSON string.
    with np.load(path, allow_pickle=False) as npz:
        assert set(npz.files) == set(REQUIRED) | set(OPTIONAL)
        assert json.loads(str(npz["vehicle"]))["wheelbase_m"] == 2.83


def test_round_trip_minimal_run(tmp_path):
    kw = full_kwargs()
    seq = Sequence(**{k: kw[k] for k in REQUIRED})
    back = load_sequence(save_sequence(seq, tmp_path / "min.npz"))
    assert_same(seq, back)
    assert back.odo_t is None and back.vehicle is None and back.scan_max_range == math.inf
    with np.load(tmp_path / "min.npz") as npz:
        assert "odo_t" not in npz.files and "vehicle" not in npz.files


def test_save_is_atomic_and_keeps_the_exact_name(tmp_path):
    seq = Sequence(**full_kwargs())
    target = tmp_path / "run.sequence"  # no .npz suffix: numpy must not append one
    save_sequence(seq, target)
    save_sequence(seq, target)  # overwrite in place
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.sequence"]  # no temp file left
    assert load_sequence(target).n_scans == N


def test_save_into_missing_folder_fails_clearly(tmp_path):
    with pytest.raises(DataError, match="does not exist"):
        save_sequence(Sequence(**full_kwargs()), tmp_path / "nope" / "run.npz")


def test_missing_file(tmp_path):
    with pytest.raises(DataError, match="not found") as info:
        load_sequence(tmp_path / "absent.npz")
    assert "absent.npz" in str(info.value)


def test_folder_is_not_a_sequence_file(tmp_path):
    with pytest.raises(DataError, match="not a file"):
        load_sequence(tmp_path)


def test_text_file_is_not_an_npz(tmp_path):
    p = tmp_path / "notes.npz"
    p.write_text("these are not the scans you are looking for\n")
    with pytest.raises(DataError, match="not a zip archive") as info:
        load_sequence(p)
    assert "notes.npz" in str(info.value)


def test_npy_file_is_not_an_npz(tmp_path):
    p = tmp_path / "ranges.npy"
    np.save(p, np.zeros(3))
    with pytest.raises(DataError, match="single .npy array"):
        load_sequence(p)


def test_empty_archive_lists_every_missing_variable(tmp_path):
    p = _write_npz(tmp_path / "empty.npz")
    with pytest.raises(DataError, match="missing required variable") as info:
        load_sequence(p)
    assert all(repr(k) in str(info.value) for k in REQUIRED)


def test_truncated_file(tmp_path):
    p = save_sequence(Sequence(**full_kwargs()), tmp_path / "run.npz")
    data = p.read_bytes()
    p.write_bytes(data[: len(data) // 2])
    with pytest.raises(DataError, match="not a readable .npz"):
        load_sequence(p)


def test_corrupt_member(tmp_path):
    p = save_sequence(Sequence(**full_kwargs()), tmp_path / "run.npz")
    with zipfile.ZipFile(p) as z:
        info = z.getinfo("scan_ranges.npy")
    data = bytearray(p.read_bytes())
    # Flip bytes inside the compressed data of scan_ranges (after its local header).
    start = info.header_offset + 30 + len(info.filename) + 20
    for i in range(start, start + 40):
        data[i] ^= 0xFF
    p.write_bytes(bytes(data))
    with pytest.raises(DataError, match="'scan_ranges' is corrupt"):
        load_sequence(p)


def _write_npz(path, **arrays):
    with open(path, "wb") as fh:
        np.savez(fh, **arrays)
    return path


def _valid_arrays() -> dict:
    seq = Sequence(**full_kwargs())
    out = {k: np.asarray(getattr(seq, k)) for k in REQUIRED}
    out["odo_t"], out["odo_speed"], out["odo_steer"] = seq.odo_t, seq.odo_speed, seq.odo_steer
    out["vehicle"] = np.array(json.dumps(seq.vehicle))
    return out


@pytest.mark.parametrize("missing", REQUIRED)
def test_missing_required_variable_is_named(tmp_path, missing):
    arrays = _valid_arrays()
    del arrays[missing]
    p = _write_npz(tmp_path / "run.npz", **arrays)
    with pytest.raises(DataError, match="missing required variable") as info:
        load_sequence(p)
    assert repr(missing) in str(info.value) and "run.npz" in str(info.value)


FILE_PROBLEMS = [
    ({"scan_t": np.array([1.0, 2.0, 2.0, 3.0, 4.0])}, "scan_t: times must be strictly increasing"),
    ({"scan_ranges": np.ones((N, B, 2))}, "scan_ranges: expected shape"),
    ({"scan_ranges": np.ones((N - 1, B))}, "scan_ranges: expected shape (N, B)"),
    ({"laser_pose": np.zeros(4)}, "laser_pose: expected shape (3,)"),
    ({"scan_angle_increment": np.array([0.1, 0.2])}, "'scan_angle_increment' must be one number"),
    ({"odo_steer": np.zeros(3)}, "odo_steer: expected shape (12,)"),
    ({"vehicle": np.array("{oops")}, "vehicle: not valid JSON"),
    ({"vehicle": np.array([1.0, 2.0])}, "'vehicle' must be a string"),
    ({"odo_t": np.array([object(), object()], dtype=object)}, "'odo_t' is corrupt or unreadable"),
]


@pytest.mark.parametrize("changes, words", FILE_PROBLEMS)
def test_bad_variables_in_a_file_are_named(tmp_path, changes, words):
    p = tmp_path / "bad.npz"
    with open(p, "wb") as fh:  # object arrays need pickle to be written
        np.savez(fh, **{**_valid_arrays(), **changes})
    with pytest.raises(DataError) as info:
        load_sequence(p)
    msg = str(info.value)
    assert words in msg and "bad.npz" in msg, msg


def test_unknown_variables_are_ignored_with_a_warning(tmp_path, caplog):
    p = _write_npz(tmp_path / "extra.npz", **_valid_arrays(), intensity=np.zeros((N, B)))
    with caplog.at_level(logging.WARNING, logger="experiments.sequence"):
        seq = load_sequence(p)
    assert seq.n_scans == N
    assert any("intensity" in r.getMessage() for r in caplog.records)


def test_loaded_arrays_are_read_only(tmp_path):
    seq = load_sequence(save_sequence(Sequence(**full_kwargs()), tmp_path / "r.npz"))
    with pytest.raises(ValueError):
        seq.scan_ranges[0, 0] = 1.0


def test_save_rejects_non_sequences(tmp_path):
    with pytest.raises(ValueError, match="Sequence"):
        save_sequence({"scan_t": [1.0]}, tmp_path / "x.npz")
    assert not os.listdir(tmp_path)
