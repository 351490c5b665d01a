"""SlamConfig: one grouped configuration, strict, and the same after a round trip through TOML."""

from __future__ import annotations

import dataclasses
import math
import tomllib
from pathlib import Path

import pytest

from experiments.bundled import presets_dir
from experiments.errors import ConfigError
from experiments.io.config_file import (
    config_diff,
    config_toml,
    load_slam_config,
    preset_path,
    preset_toml,
    presets,
)
from experiments.paper.slam import CYCAB_SLAM
from features import ExtractorParams
from slam import SlamConfig, SlamError
from slam.config import MOVED, AssociationConfig, FeaturesConfig, VehicleConfig, setting_sources


def _toml(cfg: SlamConfig) -> str:
    return config_toml(cfg, "header")


@pytest.mark.parametrize("name", sorted(presets()))
def test_every_preset_round_trips_dump_load_dump(name, tmp_path):
    cfg = load_slam_config(name)
    text = _toml(cfg)
    p = tmp_path / "c.toml"
    p.write_text(text)
    again = load_slam_config(p)
    assert again == cfg
    assert _toml(again) == text


def test_defaults_round_trip_and_every_section_is_written():
    cfg = SlamConfig()
    d = cfg.to_dict()
    assert set(d) == {
        "features",
        "association",
        "measurement",
        "vehicle",
        "start",
        "map_policy",
        "filter",
        "closure",
    }
    assert SlamConfig.from_dict(tomllib.loads(_toml(cfg))) == cfg
    # the extractor's every parameter is in the file, so the file is the whole truth
    assert set(d["features"]["extractor"]) == set(ExtractorParams.__dataclass_fields__)


def test_cycab_preset_is_experiment_2s_filter():
    assert load_slam_config("cycab") == CYCAB_SLAM


def test_victoria_park_preset_holds_what_the_experiment_runs():
    cfg = load_slam_config("victoria_park_ute")
    assert cfg.features.method == "detections"
    assert cfg.features.extractor.short_trunks is True
    assert cfg.measurement.noise == "constant"
    assert cfg.filter.first_estimates_jacobians is True
    assert cfg.start.gps_track == "slam"


def test_presets_are_presets_and_sweeps_live_apart():
    names = presets()
    assert set(names) == {"cycab", "victoria_park_ute"}
    assert all(about for about in names.values())
    assert not [p for p in presets_dir().iterdir() if p.name.startswith("sweep_")]
    sweep = Path(__file__).resolve().parents[2] / "datasets" / "sweeps" / "sweep_slam_noise.toml"
    assert sweep.is_file()
    with pytest.raises(ConfigError, match="sweep specification.*trunkslam sweep"):
        load_slam_config(sweep)


def test_unknown_keys_get_a_suggestion():
    with pytest.raises(SlamError, match=r"assocation: unknown setting.*did you mean 'association'"):
        SlamConfig.from_dict({"assocation": {}})
    with pytest.raises(
        SlamError, match=r"features\.extractor\.sigm_r_m: .*did you mean 'sigma_r_m'"
    ):
        SlamConfig.from_dict({"features": {"extractor": {"sigm_r_m": 0.01}}})
    with pytest.raises(SlamError, match=r"association\.gate_prb: .*did you mean 'gate_prob'"):
        SlamConfig.from_dict({"association": {"gate_prb": 0.9}})


@pytest.mark.parametrize("old", sorted(MOVED))
def test_a_key_of_the_flat_format_says_where_it_lives_now(old):
    with pytest.raises(SlamError, match=f"{old}: unknown setting.*now {MOVED[old]}"):
        SlamConfig.from_dict({old: 1})
    section, key = MOVED[old].split(".")  # and that is a setting of its section
    assert key in {f.name for f in dataclasses.fields(getattr(SlamConfig(), section))}


@pytest.mark.parametrize(
    ("data", "message"),
    [
        ({"features": {"extractor": {"r_min_m": -0.1}}}, "features.extractor: r_min_m"),
        ({"features": {"extractor": {"short_trunk_clearance_m": -1.0}}}, "short_trunk_clearance_m"),
        (
            {"features": {"extractor": {"short_trunk_radius_m": 0.2}}},
            r"short_trunk_radius_m.*removed",
        ),
        ({"features": {"extractor": {"sigma_r_m": "big"}}}, r"features\.extractor\.sigma_r_m"),
        ({"features": {"method": "hough"}}, r"features\.method: expected one of"),
        ({"features": {"bailey": {"detector": {"max_chord_m": math.nan}}}}, "max_chord_m"),
        ({"association": {"gate_prob": 1.0}}, r"association\.gate_prob: must be in \(0, 1\)"),
        ({"association": {"window_scans": 0}}, r"association\.window_scans"),
        ({"measurement": {"noise": "fitted"}}, r"measurement\.noise"),
        ({"vehicle": {"laser_pose": [1.0, 2.0]}}, r"vehicle\.laser_pose"),
        ({"vehicle": {"min_travel_m": -1.0}}, r"vehicle\.min_travel_m"),
        ({"start": {"gps_track": "gps"}}, r"start\.gps_track"),
        ({"map_policy": {"confirm_scans": 0}}, "confirm_scans"),
        ({"map_policy": {"policy": "vote"}}, r"map_policy\.policy: must be 'confirm' or"),
        ({"map_policy": {"existence_pd_max": 0.0}}, r"map_policy\.existence_pd_max"),
        ({"map_policy": {"existence_min_beams": 0}}, r"map_policy\.existence_min_beams"),
        ({"map_policy": {"existence_false_per_scan": 0.0}}, "existence_false_per_scan"),
        ({"map_policy": {"existence_birth_prob": 1.5}}, r"map_policy\.existence_birth_prob"),
        ({"map_policy": {"existence_remove_prob": 0.995}}, "below existence_join_prob"),
        ({"map_policy": {"existence_clutter": "bursty"}}, r"map_policy\.existence_clutter"),
        ({"map_policy": {"existence_repeat_prob": 1.0}}, r"map_policy\.existence_repeat_prob"),
        ({"map_policy": {"existence_shape_sd_m": -0.1}}, r"map_policy\.existence_shape_sd_m"),
        ({"filter": {"first_estimates_jacobians": 1}}, r"filter\.first_estimates_jacobians"),
        ({"vehicle": 3}, "vehicle: expected a table"),
    ],
)
def test_bad_values_name_the_key(data, message):
    with pytest.raises(SlamError, match=message):
        SlamConfig.from_dict(data)


def test_with_replaces_by_dotted_path_and_checks():
    cfg = SlamConfig().with_(
        **{"association.method": "nn", "features.extractor.short_trunks": False}
    )
    assert cfg.association == AssociationConfig(method="nn")
    assert cfg.features.extractor.short_trunks is False
    assert cfg.features == FeaturesConfig(extractor=ExtractorParams(short_trunks=False))
    with pytest.raises(SlamError, match="association.method"):
        SlamConfig().with_(**{"association.method": "hough"})


def test_a_preset_name_or_a_path(tmp_path):
    assert preset_path("cycab") == presets_dir() / "cycab.toml"
    with pytest.raises(ConfigError, match=r"presets: \['cycab', 'victoria_park_ute'\]"):
        preset_path("nope")


def test_config_pickles_for_the_workers():
    import pickle

    cfg = load_slam_config("victoria_park_ute")
    assert pickle.loads(pickle.dumps(cfg)) == cfg


def test_a_configuration_made_for_another_car_is_warned(caplog):
    """The cycab preset claims the simulated Cycab; on the ute (the Victoria Park preset's car)
    it is warned about, naming both cars, and the ute's preset on the Cycab too. The built-in
    settings claim no car: no warning."""
    import dataclasses as dc

    import numpy as np

    from experiments.sim import CycabParams, simulate_cycab_run
    from slam import run_slam

    seq = simulate_cycab_run(np.random.default_rng(2), "tree_park", CycabParams(n_scans=15))
    ute = dc.replace(
        seq, vehicle={"model": "ackermann", "wheelbase_m": 2.83, "encoder_offset_m": 0.76}
    )
    with caplog.at_level("WARNING", logger="slam.checks"):
        run_slam(seq, CYCAB_SLAM)
        run_slam(ute, SlamConfig(), warm_up=False)
    assert not [r for r in caplog.records if "made for a car" in r.message]
    caplog.clear()
    with caplog.at_level("WARNING", logger="slam.checks"):
        run_slam(ute, CYCAB_SLAM, warm_up=False)
    (msg,) = [r.message for r in caplog.records if "made for a car" in r.message]
    assert "wheelbase 1.2 m" in msg and "has 2.83 m (0.76 m)" in msg
    caplog.clear()
    with caplog.at_level("WARNING", logger="slam.checks"):
        run_slam(seq, load_slam_config("victoria_park_ute").with_(**{"features.method": "paper"}))
    (msg,) = [r.message for r in caplog.records if "made for a car" in r.message]
    assert "wheelbase 2.83 m" in msg and "has 1.2 m (0 m)" in msg


# ---- presets are diffs; every default has its source; one gate default --------------------------


def _leaves(d: dict, path: str = "") -> set[str]:
    out = set()
    for k, v in d.items():
        where = f"{path}.{k}" if path else k
        out |= _leaves(v, where) if isinstance(v, dict) else {where}
    return out


@pytest.mark.parametrize("name", sorted(presets()))
def test_a_preset_holds_only_what_differs_from_the_defaults(name, tmp_path):
    text = Path(str(presets_dir() / f"{name}.toml")).read_text()
    assert len(text.splitlines()) < 60
    cfg = load_slam_config(name)
    stored = tomllib.loads(text)
    assert stored == tomllib.loads(preset_toml(cfg))  # nothing a default already says
    assert stored == config_diff(cfg.to_dict(), SlamConfig().to_dict())
    # the file a run writes holds every setting, a preset's diff included
    full = tomllib.loads(config_toml(cfg))
    assert _leaves(full) >= _leaves(SlamConfig().to_dict()) - {"association.params"}
    assert _leaves(stored) < _leaves(full)


def test_a_preset_diff_reads_back_and_keeps_a_noise_model_whole():
    cfg = SlamConfig().with_(**{"measurement.constant_noise.other.range_sigma_m": 0.5})
    diff = config_diff(cfg.to_dict(), SlamConfig().to_dict())
    assert set(diff["measurement"]["constant_noise"]["other"]) == {
        "range_sigma_m",
        "range_sigma_per_m",
        "bearing_sigma_rad",
        "cross_range_sigma_m",
    }
    assert SlamConfig.from_dict(tomllib.loads(preset_toml(cfg))) == cfg
    assert tomllib.loads(preset_toml(SlamConfig())) == {}


@dataclasses.dataclass(frozen=True)
class _Claimed(SlamConfig):
    """Built-in settings that claim a car (the neutral ones claim none)."""

    vehicle: VehicleConfig = dataclasses.field(
        default_factory=lambda: VehicleConfig(calibrated_for=(1.2, 0.0))
    )


def test_a_setting_the_diff_cannot_carry_is_refused(monkeypatch):
    """None over a built-in value is no TOML value: preset_toml refuses it rather than write a
    preset that reads back otherwise."""
    import slam

    monkeypatch.setattr(slam, "SlamConfig", _Claimed)
    assert tomllib.loads(preset_toml(_Claimed())) == {}
    with pytest.raises(ConfigError, match="diff"):
        preset_toml(_Claimed(vehicle=VehicleConfig(calibrated_for=None)))


def test_every_default_names_its_source():
    """grep finds each default in slam/config.py (or, for the extractors' parameters, in
    features/, which imports nothing of slam) with a one-line source."""
    kinds = ("paper", "simulator", "sensor model", "calibration", "design")
    rows = setting_sources()
    assert len(rows) > 90
    bad = [path for path, _, source in rows if source.split(":")[0] not in kinds]
    assert not bad, f"settings without a source: {bad}"
    assert all("\n" not in source for _, _, source in rows)
    sources = {path: source for path, _, source in rows}
    assert "Victoria Park" in sources["closure.tree_sd_m"]
    assert sources["association.gate_prob"].startswith("simulator")


def test_gate_prob_has_one_default():
    """The association gate's one default is the config's; the associators take it from their
    caller (the association study names its own)."""
    import inspect

    from association import SlidingWindowAssociator, associate, associate_detailed

    for fn in (associate, associate_detailed, SlidingWindowAssociator):
        param = inspect.signature(fn).parameters["gate_prob"]
        assert param.default is inspect.Parameter.empty, fn
    assert AssociationConfig().gate_prob == 0.999


BEGIN, END = "<!-- settings: begin -->", "<!-- settings: end -->"


def settings_table() -> str:
    """The configuration reference's table: every setting, its default and its source."""
    rows = ["| setting | default | source |", "|---|---|---|"]
    for path, value, source in setting_sources():
        shown = repr(value) if isinstance(value, str) else str(value).replace("|", "\\|")
        rows.append(f"| `{path}` | `{shown}` | {source} |")
    return "\n".join(rows)


def test_the_configuration_page_shows_every_default_and_its_source():
    page = Path(__file__).resolve().parents[2] / "docs" / "configuration.md"
    text = page.read_text()
    shown = text.split(BEGIN)[1].split(END)[0].strip()
    assert shown == settings_table(), (
        "regenerate the table: tests/slam/test_config.py settings_table()"
    )
