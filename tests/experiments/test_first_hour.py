"""What a new user meets first (issue 44): help that reads cleanly, -v after the command, clear
refusals, counts in words, the licence, and summaries that say why a figure is missing."""

from __future__ import annotations

import json
import re
import tomllib
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from typer.testing import CliRunner

from experiments.cli import app
from experiments.errors import ConfigError
from experiments.eval.missing import null_scores
from experiments.io.config_file import load_slam_config
from experiments.pipeline.slam import missing_reasons
from experiments.render.cli_style import counted, hoist_verbose

REPO = Path(__file__).resolve().parents[2]
runner = CliRunner()


def _help(*command: str) -> str:
    res = runner.invoke(app, [*command, "--help"], env={"COLUMNS": "200"})
    assert res.exit_code == 0, res.output
    return res.output


@pytest.mark.parametrize(
    "command",
    [(), ("slam",), ("simulate",), ("extract",), ("convert", "rosbag"), ("bench", "slam")],
)
def test_help_shows_no_bool_type_and_arguments_in_capitals(command):
    text = _help(*command)
    assert "<bool>" not in text and "{" not in text, text
    usage = next(ln for ln in text.splitlines() if "Usage:" in ln)
    args = {"slam": "[INPUT]", "simulate": "SCENE", "extract": "INPUT", "convert": "BAG"}
    if command and command[0] in args:
        assert usage.split()[-1] == args[command[0]], usage


def test_verbose_after_the_command_is_the_apps_option():
    assert hoist_verbose(["slam", "run.npz", "-v"]) == ["-v", "slam", "run.npz"]
    assert hoist_verbose(["slam", "--verbose", "x", "--", "-v"]) == [
        "--verbose",
        "slam",
        "x",
        "--",
        "-v",
    ]
    res = runner.invoke(app, ["presets", "-v"])
    assert res.exit_code == 0, res.output
    assert "cycab" in res.output


def test_a_refused_choice_has_no_pydantic_prefix():
    res = runner.invoke(app, ["slam", "x.npz", "--features", "hough"])
    assert res.exit_code == 2
    text = " ".join(res.output.replace("│", " ").split())
    assert "'hough' is not one of 'paper', 'geometric'" in text and "Value error" not in text


def test_a_misspelt_preset_gets_a_did_you_mean():
    with pytest.raises(ConfigError, match="did you mean 'victoria_park_ute'"):
        load_slam_config("victoria_parkute")
    with pytest.raises(ConfigError) as info:
        load_slam_config("zzzz")
    assert "did you mean" not in str(info.value)


def test_counts_in_words():
    assert [counted(n, "scan") for n in (0, 1, 2)] == ["0 scans", "1 scan", "2 scans"]


def test_the_licence_is_the_one_pyproject_names():
    meta = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]
    assert meta["license"] == "BSD-3-Clause" and meta["license-files"] == ["LICENSE"]
    text = (REPO / "LICENSE").read_text()
    assert text.startswith("BSD 3-Clause License") and "Neither the name" in text
    assert re.search(r"^/dist/$", (REPO / ".gitignore").read_text(), re.MULTILINE)


def test_not_computed_names_the_rule_and_its_count():
    """478 fixes within the run, none vouched for and none within 25 ms of a scan: each missing
    figure says which fixes its rule counts, not "too few GPS fixes (478)"."""
    gps = {"matched": 478, "jumps": 476, "all_rmse": 0.5, "vouched": 0, "vouched_rmse": np.nan}
    gps |= {"rfs_rmse": np.nan, "clean_rmse_aligned": np.nan, "clean_rmse": 0.4}
    seq = SimpleNamespace(scan_t=np.array([0.0, 47.8]))
    summary = {"gps": gps}
    why = null_scores(summary, reasons=missing_reasons(seq, summary))["not_computed"]
    assert set(why) == {"gps.vouched_rmse", "gps.rfs_rmse", "gps.clean_rmse_aligned"}
    assert "none of the 478 fixes within the run is vouched for" in why["gps.vouched_rmse"]
    assert "within 25 ms of a scan" in why["gps.rfs_rmse"]
    assert (
        "at least 3 fixes" in why["gps.clean_rmse_aligned"]
        and "2 are" in why["gps.clean_rmse_aligned"]
    )


def test_each_warning_once_per_command():
    import logging

    from experiments.exec.once import OnceFilter

    f = OnceFilter()
    rec = [logging.makeLogRecord({"levelno": lv, "msg": m, "args": a}) for lv, m, a in [
        (logging.WARNING, "x = %d", (1,)),
        (logging.WARNING, "x = %d", (1,)),
        (logging.WARNING, "x = %d", (2,)),
        (logging.INFO, "step", ()),
        (logging.INFO, "step", ()),
    ]]  # fmt: skip
    assert [f.filter(r) for r in rec] == [True, False, True, True, True]


@pytest.mark.slow
def test_the_window_experiments_say_their_confirm_scans_and_warn_nothing(caplog):
    """association-in-the-loop's K = 2 window: confirm_scans min(3, K) in its configuration, the
    run identical to the one that warned, and no warning."""
    from experiments.paper.association_loop import _config
    from experiments.sim import CycabParams, simulate_cycab_run
    from slam import SlamConfig, run_slam

    seq = simulate_cycab_run(np.random.default_rng(1), "tree_park", CycabParams(n_scans=60))
    base = SlamConfig()
    ours = _config(base, "ihgr-window", 2)
    assert ours.map_policy.confirm_scans == 2 and base.map_policy.confirm_scans == 3
    with caplog.at_level("WARNING"):
        a = run_slam(seq, ours)
    assert not [r for r in caplog.records if r.levelno >= 30], caplog.text
    b = run_slam(
        seq, base.with_(**{"association.method": "ihgr-window", "association.window_scans": 2})
    )
    assert "confirm_scans = 3" in caplog.text  # the setting the experiment no longer has
    assert np.array_equal(a.pose, b.pose) and np.array_equal(a.landmark_xy, b.landmark_xy)


HEAVY = ("scipy.stats", "gtsam", "rerun", "matplotlib", "dask", "numba", "numpy")
_PROBE = """
import atexit, sys
atexit.register(lambda: print("LOADED", *[m for m in {heavy!r} if m in sys.modules]))
sys.argv = ["trunkslam", *{args!r}]
from experiments.cli import app
app()
"""


def _loaded(args: list[str], cwd: Path) -> list[str]:
    import subprocess
    import sys

    code = _PROBE.format(heavy=HEAVY, args=args)
    res = subprocess.run([sys.executable, "-c", code], cwd=cwd, capture_output=True, text=True)
    line = next(ln for ln in res.stdout.splitlines() if ln.startswith("LOADED"))
    return line.split()[1:]


@pytest.mark.slow
def test_the_first_answers_load_no_heavy_package(tmp_path):
    """Importing the command line, listing the presets, a command's help and a refused input
    load none of numpy, numba, scipy.stats, gtsam, rerun, matplotlib, dask (the `bench startup`
    figures; the time itself is measured there, not asserted)."""
    assert _loaded([], tmp_path) == []  # no arguments: the help, exit 0 or 2
    assert _loaded(["presets"], tmp_path) == []
    assert _loaded(["slam", "--help"], tmp_path) == []
    assert _loaded(["slam", "missing.npz"], tmp_path) == []
    assert _loaded(["extract", "missing.npz"], tmp_path) == []
    (tmp_path / "run.npz").write_bytes(b"")  # a misspelt preset is refused before the input loads
    assert _loaded(["slam", "run.npz", "--config", "victoria_park"], tmp_path) == []
    assert _loaded(["slam", "run.npz", "--config", "missing.toml"], tmp_path) == []


@pytest.mark.slow
def test_bench_startup_times_each_answer():
    from experiments.bench.startup import COMMANDS, FIRST_LINE, bench_startup, format_table

    rows = bench_startup(repeats=1)
    commands = ["trunkslam " + " ".join(a) for a, _ in COMMANDS]
    assert [r["command"] for r in rows] == [*commands, FIRST_LINE]
    assert all(r["wall_s"] > 0 and r["cpu_s"] > 0 and r["runs"] == 1 for r in rows)
    assert "`trunkslam slam missing.npz`" in format_table(rows)


def test_the_readmes_run_time_is_the_manifests():
    """The README's duration of `make reproduce` is the snapshot's, as the docs' `duration`
    macro prints it, not a figure typed once and left behind."""
    from experiments.render.report import Snapshot

    snap = Snapshot(REPO / "docs" / "results")
    cores = snap.manifest()["machine"].split(", ")[1]  # "2 cores"
    readme = " ".join((REPO / "README.md").read_text().split())
    assert f"about {snap.duration()} on two cores" in readme and cores == "2 cores"


def test_durations_for_planning():
    from experiments.render.report import Snapshot, format_duration

    assert [format_duration(s) for s in (40.4, 154.0, 1031.0, 7200.0)] == [
        "40 s",
        "2.6 min",
        "17.2 min",
        "2.0 h",
    ]
    snap = Snapshot(REPO / "docs" / "results")
    seconds = snap.manifest()["seconds"]
    assert snap.duration("table3 table4") == format_duration(seconds["table3 table4"])
    assert snap.duration() == format_duration(sum(seconds.values()))
    # an experiment only a later run recorded: that run's manifest
    cal = json.loads((REPO / "docs/results/manifest_results_cal3.json").read_text())
    want = format_duration(cal["seconds"]["victoria-park-calibration"])
    assert snap.duration("victoria-park-calibration") == want


def warn_twice(cfg, seed) -> int:  # noqa: ARG001 (a trial's signature)
    """A trial that meets the same condition twice (module level: sent to the workers)."""
    import logging
    import os

    for _ in range(2):
        logging.getLogger("experiments.probe").warning("the same setting, again")
    return os.getpid()


@pytest.mark.slow
def test_a_worker_shows_each_warning_once(capfd):
    """Eight trials in two worker processes, each trial warning twice: the warning shows at
    most once per worker (before, every trial's every warning reached stderr)."""
    from experiments.exec.local import ProcessExecutor

    with ProcessExecutor(2) as executor:
        pids = executor.map(warn_twice, list(range(8)), chunksize=1)
    err = capfd.readouterr().err
    shown = err.count("WARNING the same setting, again")
    assert 1 <= shown <= len(set(pids)) <= 2, err
