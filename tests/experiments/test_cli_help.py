"""The command line describes itself: version, experiment names, defaults and units; progress
and -v."""

from __future__ import annotations

import io
import logging
from importlib.metadata import version

import typer
from rich.console import Console
from support import simulated_scan_file
from typer.testing import CliRunner

from experiments.cli import ExperimentName, app
from experiments.paper.runner import EXPERIMENTS
from experiments.render.progress import Progress

runner = CliRunner()


def test_version():
    res = runner.invoke(app, ["--version"])
    assert res.exit_code == 0 and res.output.strip() == f"trunkslam {version('trunkslam')}"


def test_reproduce_help_lists_every_experiment_with_a_line():
    res = runner.invoke(app, ["reproduce", "--help"], env={"COLUMNS": "120"})
    assert res.exit_code == 0
    assert {e.value for e in ExperimentName} == set(EXPERIMENTS)
    for name in EXPERIMENTS:
        assert f"{name}:" in res.output or f"{name}, " in res.output, name


def _options(cmd, prefix=""):
    """(command --option, parameter) of every option of the typer app's click tree."""
    if hasattr(cmd, "commands"):
        for name, sub in cmd.commands.items():
            yield from _options(sub, f"{prefix} {name}")
    else:
        for p in cmd.params:
            if p.param_type_name == "option" and p.name != "help":
                yield f"{prefix.strip()} --{p.name}", p


def test_every_option_shows_its_default():
    """A default is shown by typer unless it is None; then the help must say it."""
    missing = []
    for where, p in _options(typer.main.get_command(app)):
        if p.required or p.is_flag or p.name in ("version", "verbose"):
            continue
        if p.default is None and "[default:" not in (p.help or ""):
            missing.append(where)
        if p.default is not None and not p.show_default and p.show_default is not None:
            missing.append(where)
    assert not missing, missing


def test_options_with_quantities_state_their_unit():
    units = {"sigma_r": "m", "noise": "m", "initial_heading": "rad", "scans": "s"}
    for where, p in _options(typer.main.get_command(app)):
        if p.name in units:
            assert f"{units[p.name]}" in p.help.replace(",", " ").split(), where


def _count_to_1000(every_s: float) -> None:
    quiet = Console(file=io.StringIO(), force_terminal=False)
    with Progress(every_s=every_s, console=quiet) as progress:
        for k in range(1, 1001):
            progress("slam", k, 1000)


def test_progress_off_a_terminal_prints_few_plain_lines(capsys, caplog):
    with caplog.at_level(logging.WARNING, logger="trunkslam.progress"):
        _count_to_1000(every_s=1e9)
    lines = capsys.readouterr().err.splitlines()
    assert lines[0].startswith("slam: 1/1000") and lines[-1].startswith("slam: 1000/1000 (100%)")
    assert len(lines) == 2  # the first and the last; every_s throttles the rest
    assert not caplog.records


def test_progress_lines_are_logged_instead_when_verbose(capsys, caplog):
    with caplog.at_level(logging.INFO, logger="trunkslam.progress"):
        _count_to_1000(every_s=0.0)
    msgs = [r.getMessage() for r in caplog.records]
    assert len(msgs) == 1000 and msgs[499].startswith("slam: 500/1000 (50%)")
    plain = [ln for ln in capsys.readouterr().err.splitlines() if ln.startswith("slam:")]
    assert not plain  # no plain line beside the logged one


def test_progress_on_a_terminal_draws_rich_bars_with_elapsed_and_eta():
    buf = io.StringIO()
    term = Console(file=buf, force_terminal=True, width=120)
    with Progress(console=term) as progress:
        for k in range(1, 51):
            progress("extract", k, 50)
    out = buf.getvalue()
    assert "extract" in out and "50/50" in out and "elapsed" in out and "left" in out


def test_verbose_logs_progress_detail(tmp_path):
    scan = simulated_scan_file(tmp_path)
    args = ["extract", str(scan), "--out", str(tmp_path / "f.json")]
    quiet = runner.invoke(app, args)
    loud = runner.invoke(app, ["-v", *args])
    assert quiet.exit_code == 0 and loud.exit_code == 0
    assert "INFO extract: 1/1 (100%)" in loud.output
    assert "INFO" not in quiet.output


def test_convert_victoria_park_shows_its_progress(tmp_path, vp_dir):
    out = tmp_path / "vp.npz"
    res = runner.invoke(app, ["-v", "convert", "victoria-park", "--full", "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert "INFO reading Victoria Park: 0/3 (0%)" in res.output
    assert "INFO reading Victoria Park: 3/3 (100%)" in res.output  # detections, odometry, GPS
    assert "INFO writing vp.npz: 1/1 (100%)" in res.output and out.stat().st_size > 0


def test_bench_commands_show_their_progress():
    res = runner.invoke(app, ["-v", "bench", "raycast", "--repeats", "1"])
    assert res.exit_code == 0, res.output
    assert "INFO ray casting scenes: 3/3 (100%)" in res.output
    assert "| scene |" in res.output  # and the table after it
