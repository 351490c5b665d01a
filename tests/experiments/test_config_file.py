"""SLAM configuration files: round trips, presets, and errors that name the key."""

from __future__ import annotations

import math
import tomllib

import pytest
from typer.testing import CliRunner

from experiments.bundled import preset_names
from experiments.cli import app
from experiments.errors import ConfigError, DataError
from experiments.io.config_file import config_toml, load_slam_config
from slam import MapPolicy, OdometryNoise, SlamConfig, SteeringCalibration
from slam.config import (
    DEFAULT_CONSTANT_NOISE,
    AssociationConfig,
    FilterConfig,
    MeasurementConfig,
    VehicleConfig,
)
from slam.measurement import NoiseModel

runner = CliRunner()

CUSTOM = SlamConfig(
    association=AssociationConfig(gate_prob=0.99, params={"p_detect": 0.8}),
    measurement=MeasurementConfig(
        noise="constant",
        constant_noise={"bailey": NoiseModel(0.03, 0.002, 0.004, 0.0)},
        max_range_m=40.0,
    ),
    vehicle=VehicleConfig(
        odometry_noise=OdometryNoise(0.5, 0.07),
        steering=SteeringCalibration(gain=1.01, cubic_per_rad2=0.2),
        laser_pose=(3.78, 0.5, -0.02),
    ),
    map_policy=MapPolicy(confirm_scans=2, drop_after_missed=3),
    filter=FilterConfig(first_estimates_jacobians=True),
)


def test_a_configuration_round_trips_through_toml(tmp_path):
    path = tmp_path / "c.toml"
    path.write_text(config_toml(CUSTOM, "a header\nover two lines"))
    back = load_slam_config(path)
    assert back == CUSTOM
    noise = back.measurement.constant_noise
    assert noise["bailey"] == NoiseModel(0.03, 0.002, 0.004, 0.0)
    assert noise["other"] == DEFAULT_CONSTANT_NOISE["other"]  # defaults kept
    assert "paper" not in noise  # the built-in model is one for every extractor
    model = back.measurement.model_for("bailey")
    assert (model.kind, model.constant) == ("constant", NoiseModel(0.03, 0.002, 0.004, 0.0))
    assert path.read_text().startswith("# a header\n# over two lines\n")
    # infinity survives TOML too
    inf = tmp_path / "inf.toml"
    inf.write_text(config_toml(SlamConfig()))
    assert load_slam_config(inf).measurement.max_range_m == math.inf


def test_partial_files_keep_the_defaults(tmp_path):
    path = tmp_path / "p.toml"
    path.write_text(
        "[association]\ngate_prob = 0.95\n[vehicle.odometry_noise]\nspeed_sigma_mps = 1\n"
    )
    cfg = load_slam_config(path)
    assert cfg == SlamConfig().with_(
        **{
            "association.gate_prob": 0.95,
            "vehicle.odometry_noise": OdometryNoise(speed_sigma_mps=1.0),
        }
    )


@pytest.mark.parametrize(
    "text, words",
    [
        ("[association]\ngate_prbo = 0.9\n", ["association.gate_prbo", "unknown setting"]),
        (
            "[vehicle.odometry_noise]\nspeed_sigma = 1.0\n",
            ["vehicle.odometry_noise.speed_sigma", "unknown"],
        ),
        ('[association]\ngate_prob = "high"\n', ["association.gate_prob", "expected a number"]),
        ("[association]\ngate_prob = 1.5\n", ["association.gate_prob", "(0, 1)"]),
        ("[vehicle.odometry_noise]\nspeed_sigma_mps = -0.1\n", ["speed_sigma_mps", ">= 0"]),
        ("[map_policy]\nconfirm_scans = 2.5\n", ["map_policy.confirm_scans", "whole number"]),
        ("[vehicle]\nlaser_pose = [1.0, 2.0]\n", ["vehicle.laser_pose", "3 numbers"]),
        (
            "[filter]\nfirst_estimates_jacobians = 1\n",
            ["filter.first_estimates_jacobians", "true or false"],
        ),
        (
            "[measurement.constant_noise.bailey]\nrange_sigma_m = 0.1\n",
            ["measurement.constant_noise.bailey", "missing"],
        ),
        ("[vehicle]\nodometry_noise = 3\n", ["vehicle.odometry_noise", "table"]),
        ("[vehicle.steering]\ngain = -1.0\n", ["SteeringCalibration.gain", "> 0"]),
        ("[vehicle.steering]\ncubic = 0.2\n", ["vehicle.steering.cubic", "unknown setting"]),
    ],
)
def test_bad_settings_name_the_key(tmp_path, text, words):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(ConfigError) as info:
        load_slam_config(path)
    msg = str(info.value)
    assert "bad.toml" in msg and all(w in msg for w in words), msg


def test_unreadable_files_are_data_errors(tmp_path):
    with pytest.raises(DataError, match="not found"):
        load_slam_config(tmp_path / "none.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("gate_prob = = 1\n")
    with pytest.raises(DataError, match="not valid TOML"):
        load_slam_config(bad)
    with pytest.raises(ConfigError, match="victoria_park_ute"):
        load_slam_config("no_such_preset")


def test_presets():
    assert set(preset_names()) >= {"cycab", "victoria_park_ute"}
    from experiments.paper.slam import CYCAB_SLAM, Exp2Config

    assert load_slam_config("cycab") == CYCAB_SLAM == Exp2Config().slam
    # the defaults but the odometry model's pose floor, which the simulated car does not have,
    # the paper-faithful extractor, the tree park's measurement calibration and the car claimed
    back = {
        "vehicle.odometry_noise": OdometryNoise(),
        "features.extractor.short_trunks": True,
        "measurement": SlamConfig().measurement,
        "vehicle.calibrated_for": None,
    }
    assert CYCAB_SLAM.measurement != SlamConfig().measurement
    assert CYCAB_SLAM.with_(**back) == SlamConfig()
    vp = load_slam_config("victoria_park_ute")
    assert vp.filter.first_estimates_jacobians and vp.vehicle.laser_pose[:2] == (3.78, 0.5)
    assert 0.1 < vp.vehicle.odometry_noise.speed_sigma_mps < 2.0
    assert vp.measurement.model_for("bailey").kind == "constant"


def test_cli_dump_config_reads_back(tmp_path):
    res = runner.invoke(app, ["slam", "--config", "victoria_park_ute", "--dump-config"])
    assert res.exit_code == 0, res.output
    assert SlamConfig.from_dict(tomllib.loads(res.output)) == load_slam_config("victoria_park_ute")
    res = runner.invoke(app, ["slam", "--dump-config"])
    assert SlamConfig.from_dict(tomllib.loads(res.output)) == SlamConfig()
    res = runner.invoke(app, ["slam"])
    assert res.exit_code == 2 and "INPUT" in res.output
    bad = tmp_path / "bad.toml"
    bad.write_text("gate_prbo = 0.9\n")
    res = runner.invoke(app, ["slam", "x.npz", "--config", str(bad)])
    assert res.exit_code == 1 and "gate_prbo" in res.output and "Traceback" not in res.output
