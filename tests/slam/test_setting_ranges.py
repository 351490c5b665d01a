"""The settings that feed the filter's kernels have a range (issue 43): every `[measurement]`
and `[vehicle]` setting (the noise sections among them) and the start's sigmas are refused at
load outside the range where the maths holds, by a `SlamError` naming the setting and its range,
or run through the filter within a wall-clock bound; GTSAM's exceptions leave the smoother as a
`SlamError`.

The filter runs in a worker process (`kernel_runs.Bounded`), so a run that never ends fails the
test instead of hanging the suite.
"""

from __future__ import annotations

import copy
import dataclasses
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from kernel_runs import EXTREMES, Bounded, slam_summary
from subprocesses import error_line, trunkslam

from experiments.paper.slam import CYCAB_SLAM
from slam import SlamConfig, SlamError
from slam.config import IncrementNoise, OdometryNoise, SteeringCalibration, UnicycleNoise
from slam.sequence import MAX_VARIANCE
from slam.smoother import MEAS_TENTATIVE
from slam.validators import SETTING_TINY, SIGMA_LIMIT

TIMEOUT_S = 60.0  # a case's bound: the 6-scan drive runs in well under a second

# (path, base document): the setting at `path` (keys, or a list index last) in a document that
# is valid before the value is put in
_NOISE = CYCAB_SLAM.measurement.constant_noise["paper"]._asdict()  # a model with a 0 sigma
SETTINGS = [
    (("measurement", name), {})
    for name in ("fit_floor_range_m", "fit_floor_bearing_rad", "max_range_m")
]
SETTINGS += [
    (("measurement", "constant_noise", "paper", name), {"measurement": {"noise": "constant"}})
    for name in _NOISE
]
SETTINGS += [(("measurement", "range_bias", "paper", i), {}) for i in (0, 1)]
for section, cls in (
    ("odometry_noise", OdometryNoise),
    ("unicycle_noise", UnicycleNoise),
    ("increment_noise", IncrementNoise),
    ("steering", SteeringCalibration),
):
    SETTINGS += [(("vehicle", section, f.name), {}) for f in dataclasses.fields(cls)]
SETTINGS += [(("vehicle", "laser_pose", i), {}) for i in range(3)]
SETTINGS += [(("vehicle", "gps_antenna", i), {}) for i in range(2)]
SETTINGS += [(("vehicle", "calibrated_for", i), {}) for i in range(2)]
SETTINGS += [(("vehicle", name), {}) for name in ("max_odometry_gap_s", "min_travel_m")]
SETTINGS += [(("start", "initial_pose_sigma", i), {}) for i in range(3)]
SETTINGS += [
    (("start", name), {})
    for name in ("initial_heading_rad", "gps_fit_m", "gps_sigma_m", "heading_sigma_rad")
]
# the lists a list index goes into, as they are before it
_LISTS = {
    "range_bias": [0.0, 0.0],
    "laser_pose": [1.55, 0.0, 0.0],
    "gps_antenna": [1.55, 0.0],
    "calibrated_for": [1.2, 0.0],
    "initial_pose_sigma": [0.0, 0.0, 0.0],
}


def document(path: tuple, base: dict, value) -> dict:
    """`base` with the setting at `path` set to `value`."""
    doc = copy.deepcopy(base)
    if path[1] == "constant_noise":  # a noise model is given whole: the others at their defaults
        value = dict(_NOISE, **{path[-1]: value})
        path = path[:-1]
    elif isinstance(path[-1], int):  # an item of a list setting
        items = list(_LISTS[path[1] if path[1] == "range_bias" else path[-2]])
        items[path[-1]] = value
        value = items
        path = path[:-1]
    node = doc
    for key in path[:-1]:
        node = node.setdefault(key, {})
    node[path[-1]] = value
    return doc


def _name(path: tuple) -> str:
    """The setting's own name: its last key (the list's name for a list item)."""
    return path[-2] if isinstance(path[-1], int) else path[-1]


def _refused_or_runs(worker: Bounded, path: tuple, base: dict, value) -> str:
    """Refused at load by a `SlamError` naming the setting, or the filter's run on the drive
    returns in TIMEOUT_S with a finite last pose and covariance. "refused" or "ran"."""
    doc = document(path, base, value)
    try:
        SlamConfig.from_dict(doc)
    except SlamError as exc:
        assert _name(path) in str(exc), (path, value, str(exc))
        return "refused"
    try:
        out = worker(slam_summary, doc, timeout=TIMEOUT_S)
    except SlamError as exc:  # at the run's start: what the table's settings do together
        table = ".".join(str(k) for k in path[:-1] if isinstance(k, str))
        assert _name(path) in str(exc) or table in str(exc), (path, value, str(exc))
        return "refused"
    assert out["finite"], (path, value, out)
    return "ran"


@pytest.fixture(scope="module")
def worker():
    w = Bounded()
    yield w
    w.close()


def test_the_ranges_are_the_sequence_files_and_keep_squares_normal():
    assert SIGMA_LIMIT**2 == MAX_VARIANCE  # the largest sigma squared is the file's variance
    assert SETTING_TINY**2 > np.finfo(float).tiny and math.isfinite(SIGMA_LIMIT**4)
    assert SlamConfig() == SlamConfig.from_dict(SlamConfig().to_dict())  # the defaults load


@pytest.mark.parametrize(
    "path",
    [
        ("measurement", "fit_floor_range_m"),
        ("measurement", "fit_floor_bearing_rad"),
        ("vehicle", "odometry_noise", "floor_xy_m_per_sqrt_s"),
        ("vehicle", "odometry_noise", "floor_theta_rad_per_sqrt_s"),
    ],
)
@pytest.mark.parametrize("value", [1e300, 5e-324, 1e9])
def test_the_issues_settings_are_refused_naming_their_path_and_range(path, value):
    """1e300 here gave OverflowError tracebacks (its square); a subnormal squares to 0."""
    with pytest.raises(SlamError) as err:
        SlamConfig.from_dict(document(path, {}, value))
    text = str(err.value)
    assert text.startswith(".".join(path) + ":"), text
    assert f"[{SETTING_TINY:g}, {SIGMA_LIMIT:g}]" in text and repr(value) in text, text


@pytest.mark.parametrize(
    ("index", "value", "limit"), [(0, 1e7, "10000]"), (1, 1e5, "10000]"), (2, 4.0, "3.14159")]
)
def test_the_start_sigmas_stay_where_the_prior_keeps_the_measurements(index, value, limit):
    """A start sigma of 1e7 m or 2e6 rad made the first innovation covariance not positive
    definite by rounding (an AssociationError at the first scan, naming no setting)."""
    with pytest.raises(SlamError) as err:
        SlamConfig.from_dict(document(("start", "initial_pose_sigma", index), {}, value))
    assert f"start.initial_pose_sigma[{index}]" in str(err.value) and limit in str(err.value)


@pytest.mark.slow
def test_the_largest_and_smallest_sigmas_run(worker):
    for value in (SIGMA_LIMIT, SETTING_TINY, 0.0):
        doc = {"measurement": {"fit_floor_range_m": value}}
        doc["vehicle"] = {"odometry_noise": {"floor_xy_m_per_sqrt_s": value}}
        assert worker(slam_summary, doc, timeout=TIMEOUT_S)["finite"], value


@pytest.mark.slow
def test_every_setting_at_every_extreme_is_refused_or_runs(worker):
    verdicts = {}
    for path, base in SETTINGS:
        for value in EXTREMES:
            verdicts[(path, repr(value))] = _refused_or_runs(worker, path, base, value)
    for path, _ in SETTINGS:  # beyond the maths everywhere: subnormals, 1e300, inf, nan, 10**30
        for bad in (5e-324, 1e300, math.inf, math.nan, 10**30):
            if path[-1] in ("max_range_m", "max_odometry_gap_s") and bad in (1e300, math.inf):
                continue  # limits compared with, never squared: any size holds (inf: no limit)
            assert verdicts[(path, repr(bad))] == "refused", (path, bad)
    assert list(verdicts.values()).count("ran") >= len(SETTINGS)  # each ran with some value


_WORKER = Bounded()  # hypothesis' tests cannot take a module fixture


def teardown_module() -> None:
    _WORKER.close()


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
def test_any_setting_is_refused_or_runs_within_the_bound(setting, value):
    path, base = setting
    _refused_or_runs(_WORKER, path, base, value)


# ---- the smoother: GTSAM's exceptions -----------------------------------------------------------


@pytest.fixture(scope="module")
def drive_log():
    from kernel_runs import _drive

    from slam import run_slam

    return run_slam(_drive(), SlamConfig())


def test_an_indeterminate_system_is_a_slam_error_naming_gtsams_reason(drive_log):
    """A landmark measured at 1e-300 m (a valid positive range) leaves it undetermined: iSAM2
    throws GTSAM's IndeterminateSystemException (a RuntimeError), which escaped before."""
    from slam.smoother import SmootherOptions, problem_from_log, smooth

    problem = problem_from_log(drive_log)
    assert problem.n_measurements > 0
    z = problem.meas_z.copy()
    z[0, 0] = 1e-300
    bad = dataclasses.replace(problem, meas_z=z)
    with pytest.raises(SlamError) as err:
        smooth(bad, SmootherOptions(solver="isam2"))
    text = str(err.value)
    assert text.startswith("smoother: GTSAM could not solve the problem (smooth)"), text
    assert "Indeterminate linear system" in text and "range near 0 m" in text, text
    assert smooth(problem, SmootherOptions(solver="isam2")).chi2 >= 0  # the good one solves


@pytest.mark.slow
def test_smooth_on_a_run_log_with_a_1e_300_m_measurement_is_one_clear_error(tmp_path):
    """`trunkslam smooth` on a run whose log holds a 1e-300 m range: exit 1, one error line
    naming GTSAM's reason, no traceback."""
    from kernel_runs import _drive

    from experiments.io.sequence_file import save_sequence

    save_sequence(_drive(), tmp_path / "drive.npz")
    proc = trunkslam(["slam", tmp_path / "drive.npz", "--out", tmp_path / "out"], tmp_path)
    assert proc.returncode == 0, proc.stderr
    log = tmp_path / "out" / "run_log.npz"
    with np.load(log) as f:
        arrays = {k: f[k] for k in f.files}
    used = np.flatnonzero(arrays["meas_kind"] != MEAS_TENTATIVE)  # what `smooth` reads
    arrays["meas_z"][used[0], 0] = 1e-300
    np.savez(log, **arrays)
    proc = trunkslam(["smooth", tmp_path / "out", "--solver", "isam2"], tmp_path)
    error_line(proc, "GTSAM", "Indeterminate")


def test_the_configuration_page_quotes_the_limits():
    from pathlib import Path

    from features.extract import MAX_ITER_LIMIT
    from features.fitting import DAMPING_STEPS
    from features.limits import PARAM_LIMIT, PARAM_TINY
    from slam.config import START_XY_SIGMA_LIMIT

    page = (Path(__file__).resolve().parents[2] / "docs" / "configuration.md").read_text()
    text = " ".join(page.split())
    for quoted in (
        f"[{SETTING_TINY:g}, {SIGMA_LIMIT:g}]",
        f"[{PARAM_TINY:g}, {PARAM_LIMIT:g}]",
        f"at most {MAX_ITER_LIMIT}.",
        f"within {START_XY_SIGMA_LIMIT:g} m",
        f"at most {DAMPING_STEPS} dampings",
    ):
        assert quoted in text, quoted
