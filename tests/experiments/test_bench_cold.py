"""`trunkslam bench cold`: what it clears to make a checkout cold, and what it refuses."""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from experiments.bench.cold import clear_caches, format_cold, keep_rows, project_root, read_cold
from experiments.cli import app
from experiments.errors import DataError
from experiments.io.provenance import machine


def test_clear_caches_removes_numba_and_pytest_caches_but_not_the_venv(tmp_path):
    (tmp_path / "features" / "__pycache__").mkdir(parents=True)
    for name in ("extract.kernel-12.py311.nbi", "extract.kernel-12.py311.1.nbc", "x.pyc"):
        (tmp_path / "features" / "__pycache__" / name).write_bytes(b"x")
    venv_cache = tmp_path / ".venv" / "lib" / "numba" / "__pycache__"
    venv_cache.mkdir(parents=True)
    (venv_cache / "np.f-1.py311.nbi").write_bytes(b"x")
    (tmp_path / ".pytest_cache" / "d" / "numba-gw0").mkdir(parents=True)
    assert clear_caches(tmp_path) == 3
    assert sorted(p.name for p in (tmp_path / "features" / "__pycache__").iterdir()) == ["x.pyc"]
    assert (venv_cache / "np.f-1.py311.nbi").is_file()
    assert not (tmp_path / ".pytest_cache").exists()


def test_the_table_names_each_run_and_the_load(tmp_path):
    rows = [
        {"command": "make install", "run": "-", "wall_s": 61.2, "cpu_s": 50.1, "load_1min": 0.4},
        {"command": "make check", "run": "cold", "wall_s": 58.7, "cpu_s": 99.6, "load_1min": 1.2},
        {"command": "make check", "run": "warm", "wall_s": 31.4, "cpu_s": 52.0, "load_1min": 1.9},
    ]
    for r in rows:
        r["commit"] = "abc1234"
    text = format_cold(rows)
    assert "| make check | cold | abc1234 | 59 | 100 | 1.2 |" in text
    assert "| make check | warm | abc1234 | 31 | 52 | 1.9 |" in text
    assert "cores" in text.splitlines()[0]


def _row(command, run, commit, wall):
    return {
        "command": command,
        "run": run,
        "commit": commit,
        "wall_s": wall,
        "cpu_s": 2.0 * wall,
        "load_1min": 0.5,
    }


def test_read_cold_reads_back_every_row_and_an_old_table_without_commits():
    rows = [_row("make install", "-", "aaa1111", 61.0), _row("make test", "cold", "aaa1111", 900.0)]
    assert read_cold(format_cold(rows)) == rows
    old = (
        "A fresh clone (a machine)\n\n"
        "| command | run | wall (s) | CPU (s) | load before (1 min) |\n|---|---|---|---|---|\n"
        "| make check | cold | 97 | 174 | 0.9 |\n"
    )
    assert read_cold(old) == [
        {"command": "make check", "run": "cold", "commit": "-", "wall_s": 97.0, "cpu_s": 174.0,
         "load_1min": 0.9}
    ]  # fmt: skip
    with pytest.raises(DataError, match="not a measurement"):
        read_cold(old.replace("| 97 |", "| fast |"))


def test_kept_rows_fill_in_the_commands_not_measured_in_the_benchmarks_order():
    kept = [
        _row("make install", "-", "old0000", 70.0),
        _row("make check", "cold", "old0000", 97.0),
        _row("make check", "warm", "old0000", 59.0),
        _row("make test", "cold", "old0000", 900.0),
        _row("make test", "warm", "old0000", 600.0),
    ]
    new = [
        _row("make install", "-", "new1111", 65.0),
        _row("make check", "cold", "new1111", 80.0),
        _row("make check", "warm", "new1111", 50.0),
        _row("trunkslam reproduce --quick --out quick_results", "cold", "new1111", 60.0),
        _row("trunkslam reproduce --quick --out quick_results", "warm", "new1111", 15.0),
    ]
    merged = keep_rows(new, kept)
    assert [(r["command"].split()[1], r["run"], r["commit"]) for r in merged] == [
        ("install", "-", "new1111"),
        ("check", "cold", "new1111"),
        ("check", "warm", "new1111"),
        ("test", "cold", "old0000"),
        ("test", "warm", "old0000"),
        ("reproduce", "cold", "new1111"),
        ("reproduce", "warm", "new1111"),
    ]
    assert keep_rows(new, []) == new


def test_keep_that_is_not_a_bench_cold_table_is_refused_before_any_clone(tmp_path):
    other = tmp_path / "other.md"
    other.write_text("A table (a machine)\n\n| a |\n|---|\n| 1 |\n")
    elsewhere = tmp_path / "elsewhere.md"
    row = {"command": "make test", "run": "cold", "wall_s": 900.0, "cpu_s": 1700.0}
    text = format_cold([{**row, "load_1min": 0.5, "commit": "abc1234"}])
    elsewhere.write_text(text.replace(f"({machine()}", "(Another CPU, 64 cores, Python 3.11.7"))
    for keep, says in (
        (other, "no row of a `trunkslam bench cold` table"),
        (tmp_path, "folder"),
        (elsewhere, "measured on Another CPU, 64 cores, Python 3.11.7, not on this machine"),
    ):
        args = ["bench", "cold", "--commands", "check", "--keep", str(keep)]
        res = CliRunner().invoke(app, args, env={"COLUMNS": "300"})
        assert res.exit_code == 2, res.output
        assert says in res.output, res.output


def test_project_root_is_this_checkout_and_a_plain_folder_is_refused(tmp_path):
    here = Path(__file__).resolve()
    assert here.is_relative_to(project_root(here.parent))
    with pytest.raises(DataError, match="not in a git checkout"):
        project_root(tmp_path)


def test_an_unknown_command_is_refused_before_any_clone(tmp_path):
    res = CliRunner().invoke(app, ["bench", "cold", "--commands", "check,tests", "--repo", "."])
    assert res.exit_code != 0
    assert "unknown command(s) ['tests']" in res.output
