"""Every bad input a clear error: each reproducer of issue 14 (the message names the input, exit
code 1; usage errors exit 2 with a box naming the option), the silent wrong answers, a failed
experiment, and a property test over hostile sequence files and option values."""

from __future__ import annotations

import dataclasses
import hashlib
import io
import json
import math
import os
import shutil
import zipfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from support import two_landmarks_with_cross_term
from typer.testing import CliRunner

from experiments.cli import app
from experiments.io.sequence_file import load_sequence

runner = CliRunner()


def sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def one_line_error(res, *words: str) -> None:
    """Exit 1, `error: ...` naming every word, no traceback."""
    assert res.exit_code == 1, res.output
    assert res.exception is None or isinstance(res.exception, SystemExit), repr(res.exception)
    assert "error:" in res.output and "Traceback" not in res.output
    for w in words:
        assert w in res.output, (w, res.output)


def usage_error(res, option: str) -> None:
    out = " ".join(res.output.split())
    assert res.exit_code == 2 and option in out, res.output


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """A one-scan sequence and a 20-scan drive."""
    d = tmp_path_factory.mktemp("hostile")
    scan, drive = d / "scan.npz", d / "drive.npz"
    r = runner.invoke(app, ["simulate", "test_yard", "--pose", "0,0,0", "--out", str(scan)])
    assert r.exit_code == 0, r.output
    r = runner.invoke(app, ["simulate-drive", "--scans", "20", "--seed", "1", "--out", str(drive)])
    assert r.exit_code == 0, r.output
    return scan, drive


def write_npz(path: Path, arrays: dict, raw: dict | None = None) -> Path:
    """An .npz of `arrays`; `raw` maps names to member bytes written as they are."""
    with zipfile.ZipFile(path, "w") as zf:
        for k, v in arrays.items():
            buf = io.BytesIO()
            np.save(buf, v)
            zf.writestr(f"{k}.npy", (raw or {}).get(k, buf.getvalue()))
    return path


def arrays_of(path: Path) -> dict:
    with np.load(path) as z:
        return {k: z[k] for k in z.files}


# ---- the CLI reproducers -----------------------------------------------------------------------


def test_extract_sigma_r_1e300_names_the_parameter(files, tmp_path):
    scan, _ = files
    res = runner.invoke(
        app, ["extract", str(scan), "--sigma-r", "1e300", "--out", str(tmp_path / "f.json")]
    )
    one_line_error(res, "sigma_r_m")
    assert not (tmp_path / "f.json").exists()


def test_rerun_into_a_folder_or_an_unwritable_path(files, tmp_path):
    scan, drive = files
    res = runner.invoke(
        app, ["extract", str(scan), "--out", str(tmp_path / "f.json"), "--rerun", str(tmp_path)]
    )
    one_line_error(res, "--rerun", str(tmp_path), "folder")
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    bad = blocker / "x.rrd"  # a path under a file cannot be created
    res = runner.invoke(
        app, ["extract", str(scan), "--out", str(tmp_path / "f.json"), "--rerun", str(bad)]
    )
    one_line_error(res, str(blocker))
    res = runner.invoke(
        app, ["slam", str(drive), "--out", str(tmp_path / "o"), "--rerun", str(bad)]
    )
    one_line_error(res, str(blocker))


def test_outputs_equal_to_an_input_are_refused_and_the_input_kept(files, tmp_path):
    scan, drive = files
    s1, s2 = sha(scan), sha(drive)
    for args, option in [
        (["extract", str(scan), "--out", str(scan)], "--out"),
        (
            ["extract", str(scan), "--out", str(tmp_path / "f.json"), "--rerun", str(scan)],
            "--rerun",
        ),
        (["slam", str(drive), "--rerun", str(drive), "--out", str(tmp_path / "o")], "--rerun"),
        (["slam", str(drive), "--out", str(drive)], "--out"),
        (["slam", str(drive), "--out", str(drive.parent)], "--out"),
        (["simulate", str(scan), "--pose", "0,0,0", "--out", str(scan)], "--out"),
        (["export-reference", str(drive), "--out", str(drive)], "--out"),
    ]:
        res = runner.invoke(app, args)
        one_line_error(res, option)
    assert sha(scan) == s1 and sha(drive) == s2
    link = tmp_path / "link.json"
    link.symlink_to(tmp_path / "target.json")
    res = runner.invoke(app, ["extract", str(scan), "--out", str(link)])
    one_line_error(res, "symbolic link")
    assert link.is_symlink() and not (tmp_path / "target.json").exists()
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    res = runner.invoke(app, ["extract", str(scan), "--out", str(fifo)])
    one_line_error(res, "FIFO")


def test_vehicle_json_with_a_400_digit_number_or_nested_100000_deep(files, tmp_path):
    _, drive = files
    a = arrays_of(drive)
    big = dict(a, vehicle=np.array('{"model": "ackermann", "wheelbase_m": ' + "9" * 400 + "}"))
    deep = dict(a, vehicle=np.array("[" * 100_000 + "]" * 100_000))
    for name, arrays, words in [
        ("big.npz", big, "wheelbase_m"),
        ("deep.npz", deep, "nested too deeply"),
    ]:
        p = write_npz(tmp_path / name, arrays)
        res = runner.invoke(app, ["slam", str(p), "--out", str(tmp_path / "o")])
        one_line_error(res, name, "vehicle", words)


def test_scene_files_with_huge_numbers_or_deep_nesting(tmp_path):
    from experiments.bundled import scenes_dir

    scene = json.loads((scenes_dir() / "test_yard.json").read_text())
    scene["circles"][0]["radius_m"] = 12345
    big = tmp_path / "big.json"
    big.write_text(json.dumps(scene).replace("12345", "9" * 400))
    deep = tmp_path / "deep.json"
    deep.write_text("{" + '"a": {' * 50_000 + "}" * 50_001)
    for p, words in [(big, "radius_m"), (deep, "nested too deeply")]:
        res = runner.invoke(
            app, ["simulate", str(p), "--pose", "0,0,0", "--out", str(tmp_path / "s.npz")]
        )
        one_line_error(res, p.name, words)


def test_npz_header_claiming_shape_2_pow_33(files, tmp_path):
    _, drive = files
    a = arrays_of(drive)
    hdr = np.lib.format.header_data_from_array_1_0(a["scan_t"])
    hdr["shape"] = (2**33,)
    buf = io.BytesIO()
    np.lib.format.write_array_header_1_0(buf, hdr)
    p = write_npz(tmp_path / "huge.npz", a, raw={"scan_t": buf.getvalue() + a["scan_t"].tobytes()})
    res = runner.invoke(app, ["extract", str(p), "--out", str(tmp_path / "f.json")])
    one_line_error(res, "huge.npz", "scan_t", "(8589934592,)")


def test_usage_errors_exit_2_naming_the_option(files):
    scan, _ = files
    usage_error(runner.invoke(app, ["extract", str(scan), "--sigma-r", "abc"]), "--sigma-r")
    usage_error(runner.invoke(app, ["reproduce", "--seed", "-1"]), "--seed")
    usage_error(runner.invoke(app, ["convert", "nope"]), "nope")
    usage_error(runner.invoke(app, ["bench", "slam", "--trees", "-5"]), "--trees")


def test_an_input_that_cannot_be_read_is_exit_1_naming_it(tmp_path):
    fifo = tmp_path / "seq.npz"
    os.mkfifo(fifo)  # reading it would block: refused as not a file
    one_line_error(runner.invoke(app, ["extract", str(fifo)]), "seq.npz", "not a file")
    one_line_error(runner.invoke(app, ["slam", str(tmp_path)]), str(tmp_path), "not a file")


def test_odometry_steering_at_pi_2_and_speed_1e300_are_named(files, tmp_path):
    _, drive = files
    a = arrays_of(drive)
    steer, speed = a["odo_steer"].copy(), a["odo_speed"].copy()
    steer[5], speed[7] = math.pi / 2, 1e300
    for name, arrays, words in [
        ("steer.npz", dict(a, odo_steer=steer), ["odo_steer", "sample 5"]),
        ("speed.npz", dict(a, odo_speed=speed), ["odo_speed", "sample 7"]),
    ]:
        p = write_npz(tmp_path / name, arrays)
        res = runner.invoke(app, ["slam", str(p), "--out", str(tmp_path / "o")])
        one_line_error(res, name, *words)
    ok = steer.copy()
    ok[5] = 1.3  # sharp but allowed: the run works
    p = write_npz(tmp_path / "sharp.npz", dict(a, odo_steer=ok))
    res = runner.invoke(app, ["slam", str(p), "--out", str(tmp_path / "o")])
    assert res.exit_code == 0, res.output


def test_initial_heading_inf(files, tmp_path):
    _, drive = files
    res = runner.invoke(
        app, ["slam", str(drive), "--initial-heading", "inf", "--out", str(tmp_path / "o")]
    )
    one_line_error(res, "initial_heading_rad")
    assert not (tmp_path / "o").exists()


# ---- the API: a ValueError naming the parameter -------------------------------------------------


def _scan(n=361, inc=math.pi / 360):
    from features import Scan

    return Scan(np.full(n, 5.0), angle_min_rad=-math.pi / 2, angle_increment_rad=inc)


@pytest.mark.parametrize(
    "params, words",
    [
        ({"sigma_r_m": 1e300}, "sigma_r_m"),
        ({"max_iter": 2**63}, "max_iter"),
        ({"q_m2": 1e200}, "q_m2"),
        ({"sigma_r_m": math.nan}, "sigma_r_m"),
    ],
)
def test_extractor_parameters_out_of_range(params, words):
    from features import FeaturesError, extract_features

    with pytest.raises(FeaturesError, match=words):
        extract_features(_scan(), "paper", **params)


def test_bailey_with_an_extractor_parameter_is_named():
    from features import FeaturesError, extract_features

    with pytest.raises(FeaturesError, match="sigma_r_m.*bailey"):
        extract_features(_scan(), "bailey", sigma_r_m=0.02)
    with pytest.raises(FeaturesError, match="range_sigma_m"):
        extract_features(_scan(), "bailey", range_sigma_m=1e300)
    assert extract_features(_scan(), "bailey", range_sigma_m=0.1).method == "bailey"


def test_slam_run_features_not_features_or_a_callable_returning_none(files):
    from slam import SlamConfig, SlamError, run_slam
    from slam.config import StartConfig

    seq = load_sequence(files[1])
    with pytest.raises(SlamError, match="features: expected"):
        run_slam(seq, features=3.5)  # None is the configuration's method
    with pytest.raises(SlamError, match="features: scan 0 gave NoneType"):
        run_slam(seq, features=lambda k, scan: None)
    with pytest.raises(SlamError, match="features: item 0"):
        run_slam(seq, features=[None] * seq.n_scans)
    with pytest.raises(SlamError, match="start.initial_heading_rad"):
        run_slam(seq, SlamConfig(start=StartConfig(initial_heading_rad=math.nan)))


def test_presolve_no_and_max_feature_range_nan_are_refused():
    from association import AssociationError, associate
    from association.window import SlidingWindowAssociator
    from slam import SlamError
    from slam.config import MeasurementConfig

    z = np.array([[5.0, 0.1]])
    H = np.zeros((1, 2, 5))
    H[0, :, 3:] = np.eye(2)
    args = (z, np.eye(2) * 0.01, z, H, np.eye(5) * 0.01)
    for make in (
        lambda: associate(*args, method="ihgr", presolve="no", gate_prob=0.99),
        lambda: SlidingWindowAssociator(K=2, presolve="no", gate_prob=0.99),
    ):
        with pytest.raises(AssociationError, match="presolve: must be True or False"):
            make()
    with pytest.raises(SlamError, match="measurement.max_range_m"):
        MeasurementConfig(max_range_m=math.nan)


# ---- silent wrong answers ----------------------------------------------------------------------


def test_a_scan_spanning_more_than_360_degrees_is_refused():
    from features import FeaturesError

    with pytest.raises(FeaturesError, match="angle_increment_rad.*360 degrees"):
        _scan(n=800)
    assert _scan(n=720, inc=2 * math.pi / 720).n_beams == 720  # exactly one turn: fine


def test_associate_refuses_p_not_psd_in_its_cross_terms():
    """Each landmark's block is fine, their joint block is not (correlation 5): before, IHGR and
    JCBB answered differently; now every method refuses it, naming P."""
    from association import AssociationError, associate

    z, z_hat, H, P = two_landmarks_with_cross_term(0.5)
    for method in ("ihgr", "jcbb", "nn"):
        with pytest.raises(AssociationError, match="P: not positive semi-definite on the joint"):
            associate(z, np.eye(2) * 0.01, z_hat, H, P, method=method, gate_prob=0.99)
    P = two_landmarks_with_cross_term(0.05)[3]  # a valid correlation: accepted, methods agree
    out = {
        m: associate(z, np.eye(2) * 0.01, z_hat, H, P, method=m, gate_prob=0.99).tolist()
        for m in ("ihgr", "jcbb")
    }
    assert out["ihgr"] == out["jcbb"]


def test_non_finite_values_in_the_features_json_are_null(tmp_path):
    from experiments.io.features_json import load_features_json
    from experiments.io.writers import dumps_json, features_to_dict
    from features import Scan, extract_features

    scan = Scan(
        np.r_[np.full(100, 5.0), np.full(100, 9.0)], angle_min_rad=-1.5, angle_increment_rad=0.01
    )
    f = extract_features(scan, "paper")
    assert f.edge_cov.shape[0] == 1
    huge = dataclasses.replace(
        f,
        edge_cov=np.array([[[np.inf, 0.0], [0.0, 1e300]]]),
        circle_params=np.array([[1.0, 2.0, 0.3]]),
        circle_cov=np.array([np.diag([np.inf, 1.0, np.nan])]),
        circle_beams=np.array([[3, 8]]),
        circle_rms_m=np.array([np.nan]),
    )
    text = dumps_json(
        {"schema": "trunkslam.features/1", "method": "paper", "scans": [features_to_dict(huge, 0)]}
    )
    doc = json.loads(text)
    s = doc["scans"][0]
    assert s["edges"][0]["cov"] == [[None, 0.0], [0.0, 1e300]]
    assert s["circles"][0]["cov"][0][0] is None and s["circles"][0]["cov"][2][2] is None
    p = tmp_path / "f.json"
    p.write_text(text)
    back = load_features_json(p, 1)[0]
    assert np.isnan(back.circle_cov[0, 0, 0]) and back.circle_params[0, 2] == 0.3


def test_corrupt_victoria_park_file_is_named(vp_dir, tmp_path):
    """1000 bytes flipped in sick.mat: convert says which file differs from its sha256."""
    from experiments.io.victoria_park import VP_SHA256, readme_sha256

    assert readme_sha256(vp_dir) and all(
        readme_sha256(vp_dir)[k] == v for k, v in VP_SHA256.items()
    )
    copy = tmp_path / "victoria_park"
    shutil.copytree(vp_dir, copy)
    sick = copy / "partial_raw_scans_ss2002" / "sick.mat"
    sick.chmod(0o644)
    data = bytearray(sick.read_bytes())
    rng = np.random.default_rng(0)
    for i in rng.choice(np.arange(200, len(data)), 1000, replace=False):
        data[i] ^= 0xFF
    sick.write_bytes(bytes(data))
    res = runner.invoke(
        app, ["convert", "victoria-park", "--data", str(copy), "--out", str(tmp_path / "vp.npz")]
    )
    one_line_error(res, "sick.mat", "sha256")
    assert not (tmp_path / "vp.npz").exists()


# ---- a failed experiment -----------------------------------------------------------------------


@pytest.mark.slow
def test_a_failed_experiment_fails_reproduce_after_the_others(
    noise_calibration_set, tmp_path, monkeypatch
):
    """An experiment that fails on bad input: the others still run and are installed, the
    failure is in the manifest, its partial files and its old outputs are gone, exit 1."""
    import experiments.paper.calibration as calibration
    from experiments.errors import DataError

    # the old outputs: `reproduce noise-calibration --quick` (seed 0), made once a session
    out = shutil.copytree(noise_calibration_set, tmp_path / "results")
    assert (out / "noise_calibration.csv").exists()

    def broken(ctx):
        (ctx.out_dir / "noise_calibration.md").write_text("half written")
        raise DataError("corrupt.mat: not a MATLAB file")

    monkeypatch.setattr(calibration, "run", broken)
    res = runner.invoke(
        app,
        [
            "reproduce",
            "noise-calibration",
            "circle-sweep",
            "--quick",
            "--seed",
            "4",
            "--workers",  # one worker: no pool of processes to start
            "1",
            "--out",
            str(out),
        ],
    )
    one_line_error(res, "noise-calibration", "corrupt.mat", "failed")
    m = json.loads((out / "manifest.json").read_text())
    assert m["seed"] == 4 and "corrupt.mat" in m["failed"]["noise-calibration"]
    files = {p.name for p in out.iterdir()} - {"manifest.json"}
    assert files == set(m["outputs"]) and "circle_sweep.csv" in files
    assert not any(f.startswith("noise_calibration") for f in files)


def test_corrupt_victoria_park_data_fails_the_experiment_instead_of_skipping(
    vp_dir, tmp_path, monkeypatch
):
    """Missing data skips the Victoria Park parts (with a note); corrupt data is a failure."""
    from experiments.errors import DataError
    from experiments.paper.features import victoria_park_scans
    from experiments.render.viz import NullRecorder

    copy = tmp_path / "data" / "victoria_park"
    shutil.copytree(vp_dir, copy)
    dr = copy / "aa3_dr.mat"
    dr.chmod(0o644)
    dr.write_bytes(dr.read_bytes()[:-10] + b"0123456789")
    monkeypatch.setenv("TRUNKSLAM_DATA", str(tmp_path / "data"))
    with pytest.raises(DataError, match="aa3_dr.mat"):
        victoria_park_scans(True, NullRecorder())


# ---- property: hostile sequence files and option values -----------------------------------------

HOSTILE_VALUES = st.sampled_from(
    [
        np.array(np.nan),
        np.array(np.inf),
        np.array(-1e308),
        np.array(1e300),
        np.array(0.0),
        np.array([]),
        np.array("text"),
        np.zeros((2, 3, 4)),
        np.full(7, np.nan),
        np.full(20, 1e300),
        np.arange(20, dtype=np.int64) * -1,
        np.array([True, False]),
        np.array('{"model": "ackermann", "wheelbase_m": 1e999}'),
    ]
)
VARIABLES = st.sampled_from(
    [
        "scan_t",
        "scan_ranges",
        "scan_angle_min",
        "scan_angle_increment",
        "scan_max_range",
        "laser_pose",
        "odo_t",
        "odo_speed",
        "odo_steer",
        "vehicle",
        "gps_t",
        "gps_xy",
        "truth_pose",
        "truth_landmarks",
        "scan_labels",
    ]
)


@st.composite
def hostile_file(draw):
    kind = draw(st.sampled_from(["replace", "drop", "truncate", "flip"]))
    return kind, draw(VARIABLES), draw(HOSTILE_VALUES), draw(st.integers(0, 10**9))


FLOATS = st.sampled_from(["nan", "inf", "-inf", "1e300", "-1", "0", "1e-300", "0.02", "5"])


@pytest.mark.slow
@settings(
    max_examples=40,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
@given(
    case=hostile_file(),
    command=st.sampled_from(["extract", "slam", "export-reference"]),
    number=FLOATS,
)
def test_property_hostile_files_and_options(files, tmp_path_factory, case, command, number):
    """Whatever the file and the option value: exit 0 or 1, never a traceback, the input file
    unchanged."""
    kind, var, value, seed = case
    d = tmp_path_factory.mktemp("prop")
    a = arrays_of(files[1])
    path = d / "in.npz"
    if kind == "replace":
        write_npz(path, {**a, var: value})
    elif kind == "drop":
        write_npz(path, {k: v for k, v in a.items() if k != var})
    else:
        data = bytearray(files[1].read_bytes())
        rng = np.random.default_rng(seed)
        if kind == "truncate":
            data = data[: int(rng.integers(0, len(data)))]
        else:
            for i in rng.integers(0, len(data), 20):
                data[i] ^= 0xFF
        path.write_bytes(bytes(data))
    before = sha(path)
    if command == "extract":
        args = ["extract", str(path), "--sigma-r", number, "--out", str(d / "f.json")]
    elif command == "slam":
        args = [
            "slam",
            str(path),
            "--initial-heading",
            number,
            "--out",
            str(d / "o"),
            "--features",
            "bailey",
        ]
    else:
        args = ["export-reference", str(path), "--out", str(d / "ref")]
    res = runner.invoke(app, args)
    assert res.exit_code in (0, 1), (args, case, res.output, res.exception)
    assert res.exception is None or isinstance(res.exception, SystemExit), (
        case,
        repr(res.exception),
    )
    assert "Traceback" not in res.output
    assert sha(path) == before
