"""Durations a user plans with (issue 44 item 5): the times getting-started gives for
`reproduce --quick` are those of the committed `trunkslam bench cold` table
(docs/results/bench_cold.md), as the README's `make reproduce` is the manifest's
(test_first_hour.py)."""

from __future__ import annotations

from pathlib import Path

import pytest

from experiments.bench.cold import cold_seconds, format_cold
from experiments.errors import DataError
from experiments.render.report import format_duration

REPO = Path(__file__).resolve().parents[2]


def _words(path: Path) -> str:
    return " ".join(path.read_text().split())


def test_getting_started_quotes_the_bench_cold_table_for_reproduce_quick():
    table = (REPO / "docs" / "results" / "bench_cold.md").read_text()
    assert "2 cores" in table.splitlines()[0]  # "on two idle cores"
    cold = format_duration(cold_seconds(table, "trunkslam reproduce --quick", "cold"))
    warm = format_duration(cold_seconds(table, "trunkslam reproduce --quick", "warm"))
    text = _words(REPO / "docs" / "getting-started.md")
    assert (
        f"`reproduce --quick` took {cold} on a fresh clone, compiling the kernels, and {warm} "
        "run again, on two idle cores"
    ) in text


def test_the_readme_quotes_the_bench_cold_table_for_make_test():
    table = (REPO / "docs" / "results" / "bench_cold.md").read_text()
    assert "2 cores" in table.splitlines()[0]  # "on two idle cores"
    cold = format_duration(cold_seconds(table, "make test", "cold"))
    warm = format_duration(cold_seconds(table, "make test", "warm"))
    assert (
        f"`make test` took {cold} on a fresh clone, compiling the kernels, and {warm} run "
        "again, on two idle cores"
    ) in _words(REPO / "README.md")


def test_cold_seconds_reads_back_what_format_cold_wrote():
    rows = [
        {"command": "make install", "run": "-", "wall_s": 61.2, "cpu_s": 50.1, "load_1min": 0.4},
        {"command": "make check", "run": "cold", "wall_s": 148.4, "cpu_s": 221, "load_1min": 0.8},
        {"command": "make check", "run": "warm", "wall_s": 65.6, "cpu_s": 116, "load_1min": 2.0},
    ]
    text = format_cold(rows)
    assert cold_seconds(text, "make check", "cold") == 148.0
    assert cold_seconds(text, "make check", "warm") == 66.0
    with pytest.raises(DataError, match="0 rows of 'make test' run 'cold'"):
        cold_seconds(text, "make test", "cold")
    with pytest.raises(DataError, match="2 rows of 'make' run 'cold'"):
        cold_seconds(text + text, "make", "cold")
