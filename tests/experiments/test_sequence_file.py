"""The sequence file: round trips, and a clear DataError for every malformed file."""

from __future__ import annotations

import json
import logging
import math
import os
import zipfile

import numpy as np
import pytest
from support import B, N, assert_same, full_kwargs

from experiments.errors import DataError, TrunkslamError
from experiments.io.sequence_file import load_sequence, save_sequence
from slam import Sequence
from slam.sequence import OPTIONAL, REQUIRED


def test_data_error_is_a_value_error():
    assert issubclass(DataError, ValueError) and issubclass(DataError, TrunkslamError)


def test_round_trip_every_field(tmp_path):
    seq = Sequence(**full_kwargs())
    path = save_sequence(seq, tmp_path / "run.npz")
    assert path == tmp_path / "run.npz" and path.is_file()
    back = load_sequence(path)
    assert_same(seq, back)
    assert back.vehicle == seq.vehicle and back.name == "unit test run"
    # The file holds plain arrays only: it loads without pickle, vehicle is a JSON string.
    with np.load(path, allow_pickle=False) as npz:
        # every field but the other odometry kinds' readings (a car's odometry here)
        assert set(npz.files) == set(REQUIRED) | set(OPTIONAL) - {"odo_yaw_rate", "odo_pose"}
        assert json.loads(str(npz["vehicle"]))["wheelbase_m"] == 2.83


@pytest.mark.parametrize(
    ("model", "readings"),
    [("unicycle", {"odo_yaw_rate": 0.1}), ("pose-increment", {"odo_pose": None})],
)
def test_round_trip_a_robots_own_odometry(model, readings, tmp_path):
    kw = full_kwargs()
    m = kw["odo_t"].size
    extra = {
        "odo_yaw_rate": np.linspace(-0.3, 0.3, m),
        "odo_pose": np.column_stack([np.arange(m) * 0.1, np.zeros(m), np.linspace(0, 1, m)]),
    }
    kw |= {k: extra[k] for k in readings}
    kw |= {"vehicle": {"model": model}, "odo_steer": None}
    if model == "pose-increment":
        kw["odo_speed"] = None
    seq = Sequence(**kw)
    back = load_sequence(save_sequence(seq, tmp_path / "robot.npz"))
    assert_same(seq, back)
    assert back.vehicle.model == model and back.odo_steer is None
    for k in readings:
        assert np.array_equal(getattr(back, k), extra[k])


def test_round_trip_minimal_run(tmp_path):
    kw = full_kwargs()
    seq = Sequence(**{k: kw[k] for k in (*REQUIRED, "scan_ranges")})
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
    out = {k: np.asarray(getattr(seq, k)) for k in (*REQUIRED, "scan_ranges")}
    out["odo_t"], out["odo_speed"], out["odo_steer"] = seq.odo_t, seq.odo_speed, seq.odo_steer
    out["vehicle"] = np.array(json.dumps(seq.vehicle.to_dict()))
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
    with caplog.at_level(logging.WARNING, logger="experiments.io.sequence_file"):
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
