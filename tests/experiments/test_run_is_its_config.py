"""A run is its config.toml: `trunkslam slam SEQ --config OUT/config.toml` reproduces any run to
the bit, whatever options made it (simulated, the sequence's detections, raw Victoria Park
scans with an extractor, a features file), and the configurations the experiments write beside
their results reproduce their runs too."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest

from experiments.io.config_file import load_slam_config

pytestmark = pytest.mark.slow

CLI = [sys.executable, "-m", "experiments.cli"]


def _cli(*args) -> subprocess.CompletedProcess:
    env = {**os.environ, "COLUMNS": "300"}  # help boxes on one line each
    r = subprocess.run([*CLI, *map(str, args)], capture_output=True, text=True, env=env)
    assert r.returncode == 0, r.stderr[-2000:]
    return r


@pytest.fixture(scope="module")
def vp_seq(tmp_path_factory, vp_dir) -> Path:
    """Victoria Park scans 1-2000 as a sequence file, converted once."""
    seq = tmp_path_factory.mktemp("vp") / "vp.npz"
    _cli("convert", "victoria-park", "--out", seq)
    return seq


def _rerun_is_identical(seq: Path, first: Path, tmp: Path) -> dict:
    """Re-run `first`'s run from its config.toml alone; the results equal to the byte."""
    second = tmp / (first.name + "_again")
    _cli("slam", seq, "--config", first / "config.toml", "--out", second)
    for name in ("trajectory.csv", "trajectory.tum", "map.csv", "config.toml"):
        assert (second / name).read_bytes() == (first / name).read_bytes(), name
    return json.loads((second / "summary.json").read_text())


def test_a_simulated_run_with_options_is_its_config(tmp_path):
    seq = tmp_path / "run.npz"
    _cli("simulate-drive", "tree_park", "--scans", 120, "--seed", 4, "--out", seq)
    first = tmp_path / "o1"
    _cli(
        "slam", seq, "--features", "geometric", "--window", 2, "--config", "cycab",
        "--out", first,
    )  # fmt: skip
    cfg = tomllib.loads((first / "config.toml").read_text())
    assert cfg["features"]["method"] == "geometric"
    assert cfg["association"] == {**cfg["association"], "method": "ihgr-window", "window_scans": 2}
    assert cfg["vehicle"]["odometry_noise"]["floor_xy_m_per_sqrt_s"] == 0.0  # the preset's
    s = _rerun_is_identical(seq, first, tmp_path)
    assert s["features"] == "geometric" and s["association"] == "ihgr-window"


def test_a_detections_run_is_its_config(tmp_path, vp_seq):
    seq = vp_seq
    first = tmp_path / "det"
    _cli("slam", seq, "--config", "victoria_park_ute", "--association", "jcbb", "--out", first)
    s = _rerun_is_identical(seq, first, tmp_path)
    assert s["features"] == "bailey"  # the detections' method names their noise model
    assert s["association"] == "jcbb"


def test_a_raw_scan_run_is_its_config(tmp_path, vp_seq):
    seq = vp_seq
    first = tmp_path / "geo"
    _cli("slam", seq, "--config", "victoria_park_ute", "--features", "geometric", "--out", first)
    cfg = load_slam_config(first / "config.toml")
    assert cfg.features.method == "geometric" and cfg.features.extractor.short_trunks
    _rerun_is_identical(seq, first, tmp_path)


def test_a_features_file_run_is_its_config(tmp_path):
    seq = tmp_path / "run.npz"
    _cli("simulate-drive", "tree_park", "--scans", 60, "--seed", 5, "--out", seq)
    feats = tmp_path / "f.json"
    _cli("extract", seq, "--method", "bailey", "--out", feats)
    first = tmp_path / "ff"
    _cli("slam", seq, "--features-file", feats, "--out", first)
    cfg = load_slam_config(first / "config.toml")
    assert cfg.features.file == str(feats)
    s = _rerun_is_identical(seq, first, tmp_path)
    assert s["features"] == "bailey" and s["features_file"] == str(feats)


def test_the_victoria_park_experiment_writes_the_config_of_each_run(
    tmp_path, vp_seq, quick_victoria_park_set
):
    """The configuration file the experiment writes beside its table, given to `trunkslam
    slam`, gives the table's row (the geometric extractor on scans 1-2000). The experiment's
    run is the session's shortened quick one (tests/conftest.py): the files it writes are the
    same whatever the number of scans."""
    from experiments.paper.victoria_park.real_run import vp_trial

    out = quick_victoria_park_set
    name = "victoria_park_config_scans_1_2000_geometric_ihgr.toml"
    assert (out / name).is_file()
    assert len(list(out.glob("victoria_park_config_*.toml"))) == 8
    closure = load_slam_config(out / "victoria_park_config_full_detections_ihgr_closure.toml")
    assert closure.closure.enabled and closure.association.method == "ihgr"
    assert (out / "vp_closures.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    row, _ = vp_trial(
        ("x", "raw", "geometric", "ihgr", False, False)
    )  # the full-size row (quick runs a head of the data)
    _cli("slam", vp_seq, "--config", out / name, "--out", tmp_path / "again")
    s = json.loads((tmp_path / "again" / "summary.json").read_text())
    assert s["landmarks"] == row["landmarks"]
    # summary.json rounds its errors to 0.1 mm
    assert s["gps"]["all_rmse"] == pytest.approx(row["rmse_m"], rel=0, abs=5e-5)
    # the odometry-vouched fixes: the same rule from the run's summary and the table
    assert s["gps"]["vouched"] == row["fixes_vouched"] > 0.8 * s["gps"]["matched"]
    assert s["gps"]["vouched_rmse"] == pytest.approx(row["rmse_vouched_m"], rel=0, abs=5e-5)
    # the smoother after the fact scores the same fixes (the run's config.toml, whose infinite
    # max_range_m the summary's JSON cannot hold)
    _cli("smooth", tmp_path / "again")
    sm = json.loads((tmp_path / "again" / "smoother.json").read_text())
    assert sm["gps"]["vouched"] == s["gps"]["vouched"] and sm["gps"]["vouched_rmse"] > 0


def test_experiment_2_writes_each_methods_filter(tmp_path):
    from experiments.paper.reproduce import run_experiments
    from experiments.paper.slam import Exp2Config, run_config

    out = tmp_path / "r"
    run_experiments(["table3"], out_dir=out, quick=True)
    for m in ("paper", "geometric", "bailey"):
        cfg = load_slam_config(out / f"table3_config_{m}.toml")
        assert cfg == run_config(Exp2Config.quick(), m)
        assert cfg.features.method == m


def _dumped(*args) -> str:
    """What `trunkslam slam --dump-config ARGS` prints, run in this process (typer's runner):
    six processes' start-up (about 4 s of CPU each) bought nothing here; the README's recipe
    and tests/test_wheel.py run `--dump-config` as a process."""
    from typer.testing import CliRunner

    from experiments.cli import app

    res = CliRunner().invoke(app, ["slam", "--dump-config", *map(str, args)])
    assert res.exit_code == 0, res.output
    return res.stdout


def test_dump_config_is_valid_toml_that_loads_back(tmp_path):
    for preset in ("cycab", "victoria_park_ute", None):
        text = _dumped(*(["--config", preset] if preset else []))
        p = tmp_path / "d.toml"
        p.write_text(text)
        again = load_slam_config(p)
        assert _dumped("--config", p).split("\n", 1)[1] == text.split("\n", 1)[1]
        if preset:
            assert again == load_slam_config(preset)


@pytest.mark.parametrize("study", ["slam", "association", "circles"])
def test_sweep_fields_print_a_base_table_that_loads(study, tmp_path):
    from experiments.paper.sweep import load_sweep

    text = _cli("sweep", "--fields", study).stdout
    data = tomllib.loads(text)
    assert data["study"] == study and data["base"]
    # a grid over the first numeric field on top of the printed base is a valid sweep file
    key = next(k for k, v in data["base"].items() if isinstance(v, float))
    p = tmp_path / "s.toml"
    p.write_text(text + f'\n[grid]\n"{key}" = [{data["base"][key]!r}]\n')
    spec = load_sweep(p)
    assert spec.study == study and len(spec.points) == 1


def test_the_default_is_one_thing():
    """No --config means the built-in settings, and the help says so."""
    from slam import SlamConfig

    text = _cli("slam", "--dump-config").stdout
    assert tomllib.loads(text) == tomllib.loads(__import__("tomli_w").dumps(SlamConfig().to_dict()))
    help_text = " ".join(_cli("slam", "--help").stdout.split())
    assert "the built-in settings, SlamConfig()" in help_text
    assert np.isfinite(SlamConfig().vehicle.odometry_noise.floor_xy_m_per_sqrt_s)
