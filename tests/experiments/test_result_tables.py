"""Tidy result tables: the pivot helper, and the CSVs of `trunkslam reproduce --quick` read back
(one row per observation, Markdown table = pivot of the CSV). The other experiments' quick runs
are checked in their own modules (`support.assert_tidy_tables`)."""

from __future__ import annotations

import csv
import math

import pytest
from support import assert_tidy_tables

from experiments.io.writers import (
    parse_value,
    pivot,
    pivot_cells,
    read_tidy_csv,
    tidy_csv,
    write_tidy_table,
)

LONG = [
    {"method": "paper", "pillar": "d", "statistic": "ce_mean", "value": 0.1},
    {"method": "paper", "pillar": "e", "statistic": "ce_mean", "value": 0.2 + 0.1},
    {"method": "bailey", "pillar": "e", "statistic": "ce_mean", "value": math.nan},
    {"method": "paper", "pillar": "d", "statistic": "miss_rate", "value": 2},
]


def test_pivot_orders_rows_and_columns_by_first_appearance():
    rows, cols, cells = pivot(LONG, ["method", "statistic"], ["pillar"])
    assert rows == [("paper", "ce_mean"), ("bailey", "ce_mean"), ("paper", "miss_rate")]
    assert cols == [("d", "value"), ("e", "value")]
    assert cells[(("paper", "ce_mean"), ("e", "value"))] == 0.2 + 0.1
    # bailey has no pillar d: no cell (blank); its pillar e is NaN: "n/a"
    assert ((("bailey", "ce_mean"), ("d", "value"))) not in cells
    assert pivot_cells(LONG, ["method", "statistic"], ["pillar"]) == [
        ["paper", "ce_mean", "0.1", "0.3"],
        ["bailey", "ce_mean", "", "n/a"],
        ["paper", "miss_rate", "2", ""],
    ]


def test_pivot_of_several_values_puts_the_value_name_outside():
    recs = [
        {"pillar": "a", "method": "paper", "ce": 1.0, "re": 3.0},
        {"pillar": "a", "method": "bailey", "ce": 2.0, "re": 4.0},
    ]
    _, cols, _ = pivot(recs, ["pillar"], ["method"], ["ce", "re"])
    assert cols == [("paper", "ce"), ("bailey", "ce"), ("paper", "re"), ("bailey", "re")]
    assert pivot_cells(recs, ["pillar"], ["method"], ["ce", "re"]) == [["a", "1", "2", "3", "4"]]
    # one row per record, one column per measured variable: the identity
    assert pivot_cells(recs, ["pillar", "method"], (), ["ce", "re"]) == [
        ["a", "paper", "1", "3"],
        ["a", "bailey", "2", "4"],
    ]


def test_pivot_refuses_an_observation_twice_or_a_missing_identifier():
    with pytest.raises(ValueError, match="not one per observation"):
        pivot([*LONG, LONG[0]], ["method", "statistic"], ["pillar"])
    with pytest.raises(ValueError, match="identifier"):
        pivot([{"m": math.nan, "value": 1.0}], ["m"])


def test_csv_holds_full_precision_and_reads_back_exactly(tmp_path):
    text = tidy_csv(LONG)
    assert text.splitlines()[0] == "method,pillar,statistic,value"
    assert text.splitlines()[2] == "paper,e,ce_mean,0.30000000000000004"
    assert text.splitlines()[3] == "bailey,e,ce_mean,"  # NaN: an empty cell
    (tmp_path / "t.csv").write_text(text)
    back = read_tidy_csv(tmp_path / "t.csv")
    assert back[1]["value"] == 0.2 + 0.1 and back[3]["value"] == 2
    assert math.isnan(back[2]["value"])
    assert [parse_value(s) for s in ("7", "-1.5e-3", "inf", "nn", "")][:4] == [
        7,
        -1.5e-3,
        math.inf,
        "nn",
    ]


def test_write_tidy_table_writes_the_long_csv_and_the_wide_markdown(tmp_path):
    paths = write_tidy_table(
        tmp_path / "t",
        LONG,
        ["method", "statistic"],
        ["pillar"],
        labels={"statistic": "stat", "e": "pillar e"},
        title="T",
        notes="n.",
    )
    assert [p.name for p in paths] == ["t.md", "t.csv"]
    md = (tmp_path / "t.md").read_text()
    assert "| method | stat | d | pillar e |" in md and md.endswith("\nn.\n")
    rows = list(csv.DictReader((tmp_path / "t.csv").open()))
    assert len(rows) == len(LONG) and rows[0] == {
        "method": "paper",
        "pillar": "d",
        "statistic": "ce_mean",
        "value": "0.1",
    }
    assert assert_tidy_tables(tmp_path) == {"t.csv"}
    with pytest.raises(ValueError, match="not in the pivot"):
        write_tidy_table(tmp_path / "u", LONG, ["method"], ["pillar"])


@pytest.fixture(scope="module")
def quick_tables(tmp_path_factory):
    """`trunkslam reproduce table1 noise-calibration --quick`."""
    from experiments.paper.reproduce import run_experiments

    out = tmp_path_factory.mktemp("tables")
    run_experiments(["table1", "noise-calibration"], out, quick=True, seed=0)
    return out


@pytest.mark.slow
def test_quick_circle_and_calibration_tables_are_tidy(quick_tables):
    assert assert_tidy_tables(quick_tables) == {
        "table1_ce.csv",
        "table2_re.csv",
        "table1_ce_all.csv",
        "table2_re_all.csv",
        "circle_bias.csv",
        "paper_vs_bailey.csv",
        "crlb_efficiency.csv",
        "noise_calibration.csv",
        "noise_calibration_floor.csv",
    }


@pytest.mark.slow
def test_table1_has_the_papers_numbers_as_rows(quick_tables):
    from experiments.paper.circles import PAPER_TABLE1

    rows = read_tidy_csv(quick_tables / "table1_ce.csv")
    assert list(rows[0]) == ["source", "method", "pillar", "statistic", "unit", "value"]
    pub = {(r["method"], r["pillar"]): r["value"] for r in rows if r["source"] == "paper_published"}
    assert pub == {(m, p): v for m, vals in PAPER_TABLE1.items() for p, v in vals.items()}
    ours = [r for r in rows if r["source"] == "simulation" and r["statistic"] == "ce_mean"]
    assert {r["method"] for r in ours} == {"paper", "geometric", "bailey", "taubin"}
    assert all(0 < r["value"] < 0.01 and r["unit"] == "relative" for r in ours)
    # the all-pillar table has no published rows for the pillars the paper does not give
    every = read_tidy_csv(quick_tables / "table1_ce_all.csv")
    assert {r["pillar"] for r in every if r["source"] == "paper_published"} == set("defg")


@pytest.mark.slow
def test_noise_calibration_in_use_values_are_slams(quick_tables):
    """'in use' is the cycab preset's model (the simulated tables' filter)."""
    from experiments.paper.slam import CYCAB_SLAM

    rows = read_tidy_csv(quick_tables / "noise_calibration.csv")
    in_use = [r["value"] for r in rows if r["method"] == "paper" and r["source"] == "in_use"]
    assert in_use[:4] == list(CYCAB_SLAM.measurement.constant_noise["paper"])


@pytest.mark.slow
def test_range_biases_in_use_are_the_calibrations_lines(quick_tables):
    """The cycab preset's range biases are the calibration's maximum-likelihood lines,
    rounded to 0.1 mm and 0.01 mm per m, for every extractor."""
    from experiments.paper.slam import CYCAB_SLAM

    biases = CYCAB_SLAM.measurement.range_bias

    rows = read_tidy_csv(quick_tables / "noise_calibration.csv")

    def value(method, source, quantity):
        (v,) = [
            r["value"]
            for r in rows
            if (r["method"], r["source"], r["quantity"]) == (method, source, quantity)
        ]
        return v

    assert set(biases) == {"paper", "geometric", "bailey"}
    for m, (a, b) in biases.items():
        assert value(m, "fitted", "range_bias_a") == pytest.approx(a, abs=0.5e-4)
        assert value(m, "fitted", "range_bias_b") == pytest.approx(b, abs=0.5e-5)
        assert (value(m, "in_use", "range_bias_a"), value(m, "in_use", "range_bias_b")) == (a, b)


@pytest.fixture(scope="module")
def quick_victoria_park(quick_victoria_park_set):
    """`trunkslam reproduce victoria-park --quick` on shorter data (tests/conftest.py)."""
    return quick_victoria_park_set


@pytest.mark.slow
def test_quick_victoria_park_table_is_tidy(quick_victoria_park):
    from experiments.paper.victoria_park.real_run import PUBLISHED

    assert assert_tidy_tables(quick_victoria_park) == {
        "victoria_park.csv",
        "victoria_park_published.csv",
    }
    rows = read_tidy_csv(quick_victoria_park / "victoria_park.csv")
    ours = [r for r in rows if r["source"] == "ours"]
    assert len(ours) == len(rows) == 8 and all(r["scans"] in (150, 100) for r in ours)
    pub = read_tidy_csv(quick_victoria_park / "victoria_park_published.csv")
    assert [r["run"] for r in pub] == [r["run"] for r in PUBLISHED]
    assert all(r["reference"].startswith("github.com/") for r in PUBLISHED)
