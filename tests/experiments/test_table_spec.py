"""`TableSpec`: a result table declared beside its experiment and written from the study's
results by the report step (`experiments.paper.products.tables`), the same files as
`write_tidy_table` given the same records and settings."""

from __future__ import annotations

import math
from dataclasses import dataclass

from support import assert_tidy_tables

from experiments.io.writers import read_tidy_csv, write_tidy_table
from experiments.paper import products
from experiments.paper.products import TableSpec


@dataclass
class _Study:
    n_runs: int
    error: dict  # method -> mean error (m)
    ms: dict  # method -> ms per scan


def _records(st: _Study) -> list[dict]:
    return [
        {"method": m, "runs": st.n_runs, "error_m": e, "ms_per_scan": st.ms.get(m)}
        for m, e in st.error.items()
    ]


SPEC = TableSpec(
    "errors",
    _records,
    index=("method",),
    values=None,
    labels=lambda st: {"error_m": f"error over {st.n_runs} runs (m)"},
    title="Errors",
    notes=lambda st: f"best: {min(st.error, key=st.error.get)}",
)
STUDY = _Study(3, {"paper": 0.05, "bailey": 0.08, "geometric": math.nan}, {"paper": 1.5})


class _Ctx:
    def __init__(self, out_dir) -> None:
        self.out_dir = out_dir
        self.outputs: list = []


def test_a_table_spec_writes_what_write_tidy_table_writes(tmp_path):
    (tmp_path / "spec").mkdir()
    (tmp_path / "direct").mkdir()
    paths = SPEC.write(tmp_path / "spec", STUDY)
    assert [p.name for p in paths] == ["errors.md", "errors.csv"]
    write_tidy_table(
        tmp_path / "direct" / "errors",
        _records(STUDY),
        index=["method"],
        values=["runs", "error_m", "ms_per_scan"],  # what values=None means here
        labels={"error_m": "error over 3 runs (m)"},
        title="Errors",
        notes="best: paper",
    )
    for name in ("errors.md", "errors.csv"):
        assert (tmp_path / "spec" / name).read_bytes() == (tmp_path / "direct" / name).read_bytes()
    md = (tmp_path / "spec" / "errors.md").read_text()
    assert "| method | runs | error over 3 runs (m) | ms_per_scan |" in md
    assert md.rstrip().endswith("best: paper")


def test_values_none_takes_every_other_field_in_order_of_first_appearance():
    """A field that only a later record has (ms_per_scan: only paper's) is still a column."""
    records = [
        {"method": "bailey", "runs": 2, "error_m": 0.1},
        {"method": "paper", "runs": 2, "error_m": 0.2, "ms_per_scan": 1.0},
    ]
    spec = TableSpec("t", lambda _: records, index=("method",), values=None)
    md, csv_text = spec.texts(None)
    assert csv_text.splitlines()[0] == "method,runs,error_m,ms_per_scan"
    assert '"values": ["runs", "error_m", "ms_per_scan"]' in md
    assert csv_text.splitlines()[1] == "bailey,2,0.1,"


def test_the_report_step_writes_every_table_into_the_result_folder(tmp_path):
    ctx = _Ctx(tmp_path)
    other = TableSpec("other", lambda st: [{"n": st.n_runs, "value": 1.0}], index=("n",))
    products.tables(ctx, [SPEC, other], STUDY)
    assert [p.name for p in ctx.outputs] == ["errors.md", "errors.csv", "other.md", "other.csv"]
    assert assert_tidy_tables(tmp_path) == {"errors.csv", "other.csv"}
    rows = read_tidy_csv(tmp_path / "errors.csv")
    assert [r["method"] for r in rows] == ["paper", "bailey", "geometric"]
    assert math.isnan(rows[2]["error_m"]) and math.isnan(rows[1]["ms_per_scan"])
