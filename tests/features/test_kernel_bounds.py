"""Every compiled loop of the extractor ends (issue 43): the fits' damping loops are capped, every
`[features]` setting is refused at load outside the range where the kernels' maths holds (a
clear error naming it) or runs through the kernels within a wall-clock bound, and SIGTERM
during the kernels ends `extract` and `slam` within 5 s.

The kernels run in a worker process (`kernel_runs.Bounded`): a loop without an end would hold
the test's own process forever (it ignores SIGALRM), there it only fails the test.
"""

from __future__ import annotations

import dataclasses
import math
import os
import signal
import time

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from kernel_runs import EXTREMES, Bounded, extract_summary, paper_fit
from subprocesses import start

from features import ExtractorParams
from features.bailey import BaileyParams
from features.errors import FeaturesError
from features.fitting import DAMPING_STEPS
from features.limits import PARAM_LIMIT, PARAM_TINY
from slam import SlamConfig, SlamError
from slam.config import BaileyConfig

TIMEOUT_S = 60.0  # a case's bound: the drive's 6 scans take well under a second per method

# every setting of [features] that reaches a kernel: (path, method that runs it)
SETTINGS = (
    [(("extractor", f.name), "paper") for f in dataclasses.fields(ExtractorParams)]
    + [
        (("bailey", f.name), "bailey")
        for f in dataclasses.fields(BaileyConfig)
        if f.name != "detector"
    ]
    + [(("bailey", "detector", f.name), "bailey") for f in dataclasses.fields(BaileyParams)]
)


@pytest.fixture(scope="module")
def bounded():
    worker = Bounded()
    yield worker
    worker.close()


def _document(path: tuple, method: str, value) -> dict:
    """The configuration with one [features] setting at `path` set to `value`."""
    node: dict = {"method": method}
    doc = {"features": node}
    for key in path[:-1]:
        node = node.setdefault(key, {})
    node[path[-1]] = value
    return doc


def _refused_or_runs(bounded, path: tuple, method: str, value) -> str:
    """Load the configuration and run its kernels in the worker: either a `SlamError` naming
    the setting (its section path and name) or circles whose every number is finite, within
    TIMEOUT_S. Returns "refused" or "ran"."""
    try:
        out = bounded(extract_summary, _document(path, method, value), timeout=TIMEOUT_S)
    except SlamError as exc:  # at load: the setting's path and name
        text = str(exc)
        assert f"features.{'.'.join(path[:-1])}" in text and path[-1] in text, (path, text)
        return "refused"
    except FeaturesError as exc:  # at the first scan (too coarse a scan for the setting)
        assert path[-1] in str(exc), (path, str(exc))
        return "refused"
    assert all(finite for _, finite in out.values()), (path, value, out)
    return "ran"


def test_the_damping_cap_is_the_steps_from_the_least_double_past_1e12():
    """DAMPING_STEPS x10 steps take the least positive double to 1e12, so any positive damping
    ends the loop by its own test before the cap (results unchanged)."""
    lam, steps = 5e-324, 0
    while lam < 1e12:
        lam *= 10.0
        steps += 1
    assert steps == DAMPING_STEPS


@pytest.mark.parametrize("lambda0", [0.0, -1.0, -math.inf, 5e-324, 1e-320, math.nan, math.inf])
def test_the_papers_fit_returns_whatever_its_damping(bounded, lambda0):
    """Called directly (no parameter checks): a damping that is 0, negative, subnormal (it
    underflows to 0 after one accepted step: this hung forever before the cap) or not finite."""
    x0, y0, r, ok, n_iter = bounded(paper_fit, lambda0, 100, 1e-10, timeout=TIMEOUT_S)
    assert 0 <= n_iter <= 100
    if ok:  # at worst its start, the circle through the first three points: near the arc's
        assert abs(x0 - 3.0) < 0.4 and abs(y0 - 1.0) < 0.4 and 0.0 < r < 1.0


def test_the_papers_fit_with_the_largest_iteration_count_returns(bounded):
    x0, y0, r, ok, n_iter = bounded(paper_fit, 1e-150, 10_000, 0.0, timeout=TIMEOUT_S)
    assert ok and n_iter <= 10_000 and abs(r - 0.4) < 0.05


@pytest.mark.parametrize(
    ("name", "value", "words"),
    [
        ("lambda0", 5e-324, ["lambda0", f"at least {PARAM_TINY:g}"]),
        ("lambda0", 1e12, ["lambda0", f"at most {PARAM_LIMIT:g}"]),
        ("max_iter", 10**9, ["max_iter", "at most 10000"]),
        ("sigma_r_m", 1e-200, ["sigma_r_m", f"{PARAM_TINY:g}"]),
        ("q_m2", 1e300, ["q_m2", f"at most {PARAM_LIMIT:g}"]),
        ("tol", -5e-324, ["tol", f"{PARAM_TINY:g}"]),
    ],
)
def test_extreme_extractor_settings_are_refused_naming_the_setting_and_its_range(
    name, value, words
):
    with pytest.raises(SlamError) as err:
        SlamConfig.from_dict({"features": {"extractor": {name: value}}})
    for w in ["features.extractor", *words]:
        assert w in str(err.value), (w, str(err.value))


def test_the_limits_keep_the_defaults_and_their_squares_normal():
    assert ExtractorParams() == ExtractorParams(**dataclasses.asdict(ExtractorParams()))
    assert PARAM_TINY**2 > np.finfo(float).tiny and math.isfinite(PARAM_LIMIT**4)
    assert BaileyConfig() == BaileyConfig(**{f.name: getattr(BaileyConfig(), f.name) for f in
                                             dataclasses.fields(BaileyConfig)})  # fmt: skip


@pytest.mark.slow
def test_every_features_setting_at_every_extreme_is_refused_or_runs(bounded):
    """The whole [features] section (extractor, Bailey noise model and detector constants)
    times every extreme value."""
    verdicts = {}
    for path, method in SETTINGS:
        for value in EXTREMES:
            verdicts[(path, repr(value))] = _refused_or_runs(bounded, path, method, value)
    # every setting refuses the values beyond the maths: subnormals, 1e300, inf, nan, 10**30
    for path, _ in SETTINGS:
        for bad in (5e-324, 1e300, math.inf, math.nan, 10**30):
            assert verdicts[(path, repr(bad))] == "refused", path
    assert "ran" in verdicts.values()


@pytest.mark.slow
@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    setting=st.sampled_from(SETTINGS),
    value=st.one_of(
        st.sampled_from(EXTREMES),
        st.floats(allow_nan=True, allow_infinity=True),
        st.integers(min_value=-(2**70), max_value=2**70),
    ),
)
def test_any_features_setting_is_refused_or_runs_within_the_bound(setting, value):
    path, method = setting
    _refused_or_runs(_WORKER, path, method, value)


_WORKER = Bounded()  # hypothesis' tests cannot take a module fixture


def teardown_module() -> None:
    _WORKER.close()


# ---- SIGTERM in the kernels ------------------------------------------------------------------


@pytest.fixture(scope="module")
def dense_drive(tmp_path_factory):
    """60 scans of the tree park drive, each resimulated with 99,001 beams over 180 deg (the
    sequence file's largest scans): the command spends its time in the extractor's kernels,
    seconds after its first progress line (at 10 scans)."""
    from experiments.io.sequence_file import save_sequence
    from experiments.sim import CycabParams, simulate_cycab_run
    from experiments.sim.scene import load_scene
    from experiments.sim.simulate import sensor_preset, simulate_scan

    rng = np.random.default_rng(7)
    seq = simulate_cycab_run(rng, "tree_park", CycabParams(n_scans=60))
    sensor = sensor_preset("lms200", angle_increment_rad=math.pi / 99_000)
    scene = load_scene("tree_park")
    at_scans = seq.truth_pose[np.searchsorted(seq.truth_t, seq.scan_t)]  # truth at odometry rate
    ranges = np.stack([simulate_scan(scene, p, sensor, rng, seq.laser_pose)[0] for p in at_scans])
    dense = dataclasses.replace(
        seq,
        scan_ranges=ranges,
        scan_angle_min=sensor.angle_min_rad,
        scan_angle_increment=sensor.angle_increment_rad,
        scan_n_beams=None,
        scan_labels=None,
    )
    path = tmp_path_factory.mktemp("dense") / "dense.npz"
    save_sequence(dense, path)
    return path


@pytest.mark.slow
@pytest.mark.parametrize("command", ["extract", "slam"])
def test_sigterm_while_the_kernels_run_ends_the_command_within_5_s(dense_drive, tmp_path, command):
    """SIGTERM sent once the command is extracting (its first progress line), at three delays:
    it ends within 5 s, as Ctrl-C does (exit 143, one error line, no output written)."""
    out = tmp_path / ("f.json" if command == "extract" else "out")
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    # the drive is the simulated Cycab's: its preset (no built-in-settings warning before the
    # first progress line)
    config = ["--config", "cycab"] if command == "slam" else []
    for delay in (0.0, 0.4, 1.1):
        p = start([command, dense_drive, "--out", out, *config], tmp_path, env)
        line = p.stderr.readline()  # the first progress line: the kernels are compiled and run
        assert f"{command}" in line or "scan" in line, line
        time.sleep(delay)
        assert p.poll() is None, "the command ended before the signal: make the input larger"
        t0 = time.monotonic()
        p.send_signal(signal.SIGTERM)
        _, err = p.communicate(timeout=60)
        took = time.monotonic() - t0
        assert took < 5.0, (delay, took)
        assert p.returncode == 128 + signal.SIGTERM and "Traceback" not in err, err
        assert "stopped by SIGTERM" in err and not out.exists()
