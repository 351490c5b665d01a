"""The built-in settings are neutral; the simulated Cycab's values are the `cycab` preset's.

The presets resolve, setting by setting, to what they resolved to before the change
(tests/slam/data/presets_before_neutral.json, written once from commit 91b38ae and frozen): the
Victoria Park run and every simulated experiment (`CYCAB_SLAM`) are the runs they were.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from experiments.io.config_file import load_slam_config
from experiments.paper.slam import CYCAB_SLAM
from experiments.pipeline.built_in import CYCAB_ODOMETRY, NEUTRAL, built_in_note
from experiments.sim import CycabParams, simulate_cycab_run
from slam import SlamConfig
from slam.config import setting_sources

HERE = Path(__file__).resolve().parent
BEFORE = json.loads((HERE / "data" / "presets_before_neutral.json").read_text())
PAGE = HERE.parents[1] / "docs" / "configuration.md"
# Settings in which the cycab preset differs from the built-in ones but the built-in value did
# not change (the extractor's short trunks and the odometry model's pose floor: design values)
KEPT = {
    "features.extractor.short_trunks",
    "vehicle.odometry_noise.floor_xy_m_per_sqrt_s",
    "vehicle.odometry_noise.floor_theta_rad_per_sqrt_s",
}


# Settings a preset changed on purpose since the record, each a named change of its own (the
# record stays frozen; the test checks that each of these did change and nothing else did)
CHANGED_SINCE = {
    "victoria_park_ute": {
        # the calibration's range-bias step (experiments/eval/trace_bias.py, issue 39)
        "measurement.range_bias.bailey",
        # the calibration's laser-latency step (latency_profile, derive_latency; issue 39)
        "vehicle.laser_latency_s",
        # closure.tree_sd_m's procedure (view_offset) on the preset's run of scans 1-2000 gives
        # 0.04 m at the preset's laser latency (0.05 m before it); issue 39
        "closure.tree_sd_m",
    },
    "cycab": {"closure.tree_sd_m"},  # the same built-in default
}


def _leaves(d: dict, path: str = "") -> dict:
    out = {}
    for k, v in d.items():
        where = f"{path}.{k}" if path else k
        out.update(_leaves(v, where) if isinstance(v, dict) else {where: v})
    return out


def _json_plain(cfg: SlamConfig) -> dict:
    """`cfg.to_dict()` as the stored JSON holds it (tuples as lists)."""
    return json.loads(json.dumps(cfg.to_dict()))


@pytest.mark.parametrize(
    "name, now",
    [
        ("victoria_park_ute", lambda: load_slam_config("victoria_park_ute")),
        ("cycab", lambda: CYCAB_SLAM),
    ],
)
def test_a_preset_resolves_to_what_it_did_before_the_neutral_defaults(name, now):
    # every setting of the record (a setting added since is not in it: its default decides)
    before, after = _leaves(BEFORE[name]), _leaves(_json_plain(now()))
    differ = {k: (v, after.get(k, "missing")) for k, v in before.items() if after.get(k) != v}
    assert set(differ) == CHANGED_SINCE[name], f"{name}: settings changed (before, after): {differ}"
    assert len(before) > 90  # every setting, not a section


def test_the_cycab_preset_is_experiment_2s_filter_and_claims_the_cycab():
    assert load_slam_config("cycab") == CYCAB_SLAM
    car = CycabParams()
    assert CYCAB_SLAM.vehicle.calibrated_for == (car.wheelbase_m, 0.0)
    noise = CYCAB_SLAM.vehicle.odometry_noise
    assert (noise.speed_sigma_mps, noise.steer_sigma_rad) == (
        car.speed_sigma_mps,
        car.steer_sigma_rad,
    )


def test_the_built_in_measurement_model_and_car_are_neutral():
    cfg = SlamConfig()
    m = cfg.measurement
    assert (m.fit_floor_range_m, m.fit_floor_bearing_rad) == (0.0, 0.0)
    assert dict(m.range_bias) == {}
    assert set(m.constant_noise) == {"other"}
    for method in ("paper", "geometric", "bailey", "kasa"):
        model = m.model_for(method)
        assert model.range_bias == (0.0, 0.0) and model.floor == (0.0, 0.0)
    # the constant model is the Bailey detector's own published noise model
    b = cfg.features.bailey
    assert tuple(m.constant_noise["other"])[:3] == (
        b.range_sigma_m,
        b.range_sigma_per_m,
        b.bearing_sigma_rad,
    )
    assert cfg.vehicle.calibrated_for is None
    sources = {path: source for path, _, source in setting_sources()}
    for path in NEUTRAL:
        assert sources[path].split(":")[0] in ("sensor model", "design"), path
    for path in CYCAB_ODOMETRY.values():  # no neutral value: the simulator's, and said so
        mine = [s for p, s in sources.items() if p.startswith(path + ".")]
        assert any(s.startswith("simulator") for s in mine), path


def _shown(v) -> str:
    """A cell: a noise model as its four sigmas, a missing entry as "none"."""
    if v is None:
        return "none"
    text = str(list(v.values()) if isinstance(v, dict) else v)
    return f"`{text}`"


def neutral_table() -> str:
    """The configuration page's table of the settings the cycab preset changes: the built-in
    value before the neutral defaults (the Cycab's, but for `KEPT`), now, the preset's, and the
    built-in value's source; a table of settings by method (noise models, range biases) one row
    per method that differs."""
    now = {p: (v, s) for p, v, s in setting_sources()}
    cycab = {p: v for p, v, _ in setting_sources(CYCAB_SLAM)}
    rows = [
        "| setting | built-in before | built-in now | `cycab` preset | source of the built-in |",
        "|---|---|---|---|---|",
    ]
    for path, (value, source) in now.items():
        if cycab[path] == value:
            continue
        before = value if path in KEPT else cycab[path]
        if not isinstance(value, dict):
            cells = " | ".join(_shown(v) for v in (before, value, cycab[path]))
            rows.append(f"| `{path}` | {cells} | {source} |")
            continue
        for key in sorted(set(before) | set(value) | set(cycab[path])):
            three = [d.get(key) for d in (before, value, cycab[path])]
            if three[0] == three[1] == three[2]:
                continue
            cells = " | ".join(_shown(v) for v in three)
            rows.append(f"| `{path}.{key}` | {cells} | {source} |")
    return "\n".join(rows)


def test_the_configuration_page_lists_the_neutral_defaults():
    text = PAGE.read_text()
    shown = text.split("<!-- neutral: begin -->")[1].split("<!-- neutral: end -->")[0].strip()
    assert shown == neutral_table(), (
        "regenerate: tests/slam/test_neutral_defaults.py neutral_table()"
    )
    # the table's "before" column is the built-in settings the presets were resolved over
    before = _leaves(BEFORE["cycab"])
    for line in shown.splitlines()[2:]:
        path = line.split("`")[1]
        if path not in KEPT:  # a setting, or a method's entry of one
            assert any(k == path or k.startswith(path + ".") for k in before), path


@pytest.fixture(scope="module")
def cycab_run():
    return simulate_cycab_run(np.random.default_rng(0), "tree_park", CycabParams(n_scans=3))


def test_a_run_on_the_built_in_settings_is_told_and_the_cycab_gets_its_preset(cycab_run):
    note = built_in_note(cycab_run, SlamConfig())
    assert note["neutral"] == list(NEUTRAL)
    assert note["simulated_cycab"] == ["vehicle.odometry_noise"]
    assert note["suggested_preset"] == "cycab" and "--config cycab" in note["message"]
    assert built_in_note(cycab_run, CYCAB_SLAM) is None  # a preset that claims its car
    # another car: the neutral settings and the odometry noise are named, no preset suggested
    ute = dataclasses.replace(
        cycab_run, vehicle={"model": "ackermann", "wheelbase_m": 2.83, "encoder_offset_m": 0.76}
    )
    mine = SlamConfig().with_(**{"measurement.fit_floor_range_m": 0.01})
    note = built_in_note(ute, mine)
    assert "measurement.fit_floor_range_m" not in note["neutral"]
    assert note["suggested_preset"] is None and "cycab" not in note["message"].split("Cycab")[-1]


def test_trunkslam_slam_without_config_writes_the_note(cycab_run, tmp_path):
    from experiments.io.sequence_file import save_sequence
    from experiments.pipeline.slam import run_slam_file

    save_sequence(cycab_run, tmp_path / "run.npz")
    summary = run_slam_file(tmp_path / "run.npz", None, tmp_path / "out")
    on_disk = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert on_disk["built_in_settings"] == summary["built_in_settings"]
    assert summary["built_in_settings"]["suggested_preset"] == "cycab"
    cycab = run_slam_file(tmp_path / "run.npz", CYCAB_SLAM, tmp_path / "cycab")
    assert "built_in_settings" not in cycab
