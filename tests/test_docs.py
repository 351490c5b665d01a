"""The documents quote numbers only from result files: every macro of the documentation site
resolves against the snapshot `docs/results/`, the README's results-at-a-glance table is what
`trunkslam report` generates from it, and the snapshot agrees with a fresh run of the
experiments that are cheap enough to re-run here."""

from __future__ import annotations

import math
import re
from pathlib import Path

import pytest

from experiments.io.writers import read_tidy_csv
from experiments.render.report import (
    GLANCE_BEGIN,
    GLANCE_END,
    MACRO,
    ReportError,
    Snapshot,
    glance_table,
    render_macros,
)

REPO = Path(__file__).resolve().parents[1]
DOCS = REPO / "docs"
SNAPSHOT = DOCS / "results"
PAGES = sorted(p for p in DOCS.rglob("*.md") if SNAPSHOT not in p.parents)
README_MAX_LINES = 300  # the front door (issue 25)


@pytest.fixture(scope="module")
def snapshot() -> Snapshot:
    return Snapshot(SNAPSHOT)


@pytest.mark.parametrize("page", PAGES, ids=[str(p.relative_to(DOCS)) for p in PAGES])
def test_every_macro_of_a_page_resolves(page, snapshot):
    text = page.read_text()
    out = render_macros(text, snapshot, str(page))
    assert not MACRO.search(out), f"{page}: a macro is left unresolved"


def test_pages_quote_the_snapshot():
    """The experiment pages take their numbers from the snapshot, not from the text."""
    pages = sorted((DOCS / "experiments").glob("*.md"))
    assert len(pages) >= 7
    for page in pages:
        assert "{{ provenance() }}" in page.read_text(), f"{page.name} does not say its source"
        assert MACRO.search(page.read_text()), f"{page.name} quotes no result file"


def test_readme_glance_is_generated_from_the_snapshot(snapshot):
    readme = (REPO / "README.md").read_text()
    block = readme.split(GLANCE_BEGIN, 1)[1].split(GLANCE_END, 1)[0]
    assert block.strip() == glance_table(snapshot).strip(), (
        "README's results at a glance differ from the snapshot: run `trunkslam report results`"
    )
    # and it carries the paper's four tables and the real-data rows
    for what in ("Table 1", "Table 2", "Table 3", "Table 4", "Victoria Park"):
        assert what in block


def test_the_glance_reports_the_loop_closure_goals(snapshot):
    """The README's glance has every loop-closure goal's figure: the closure run's smoother
    (not the run without closure) and RFS-protocol RMSE beside the best published one, the
    orchard's closures, the drives counted and the NEES after the return."""
    rows = {r.split(" | ")[0]: r for r in glance_table(snapshot).splitlines()}
    run = "full run, published detections, ihgr, loop closure"
    n = int(snapshot.value("victoria_park", "scans", source="ours", run=run))
    smoothed = snapshot.value(
        "smoother",
        "rmse_vouched_m",
        problem=f"Victoria Park, {n} scans, loop closure",
        solver="smoother (batch)",
    )
    rfs = snapshot.value("victoria_park", "rmse_rfs_m", source="ours", run=run)
    best = min(
        r["rmse_rfs_m"]
        for r in snapshot.records("victoria_park_published")
        if math.isfinite(r["rmse_rfs_m"])
    )
    (vp,) = [r for k, r in rows.items() if "full run with loop closure" in k]
    assert vp.endswith(f" | {smoothed:.2f} m / {rfs:.2f} m |")
    assert f"best published {best:.2f} m" in vp

    def lc(scene, key):
        return snapshot.value("loop_closure", key, scene=scene, jacobians="standard", closure="on")

    (nees,) = [r for k, r in rows.items() if "with the pose NEES inside" in k]
    assert f"{lc('park', 'nees_inside_after_return'):.2f} / " in nees
    assert f" / {lc('orchard', 'nees_inside_after_return'):.2f}" in nees
    (orchard,) = [r for k, r in rows.items() if "orchard returns drifted" in k]
    assert f"{int(lc('orchard', 'with_closure_2_5_m'))} of " in orchard
    (false,) = [r for k, r in rows.items() if "false closures" in k]
    assert f" in {int(lc('park', 'runs'))} / {int(lc('orchard', 'runs'))}" in false


def test_readme_is_the_front_door():
    lines = (REPO / "README.md").read_text().splitlines()
    assert len(lines) <= README_MAX_LINES
    assert any("make reproduce" in line for line in lines)
    assert any("make test" in line for line in lines)


def test_a_macro_that_does_not_resolve_is_an_error(snapshot):
    with pytest.raises(ReportError, match="rows match"):
        render_macros('{{ cell("table3", method="no such method") }}', snapshot, "x.md")
    with pytest.raises(ReportError, match="no nope.csv"):
        render_macros('{{ cell("nope") }}', snapshot, "x.md")
    with pytest.raises(ReportError, match="unknown macro"):
        render_macros("{{ open('/etc/passwd') }}", snapshot, "x.md")
    with pytest.raises(ReportError, match="macro"):
        render_macros("{{ cell(__import__('os')) }}", snapshot, "x.md")


def test_macros_read_the_right_cell(tmp_path):
    (tmp_path / "t.csv").write_text("method,quantity,value\na,x,0.5\na,y,2.0\nb,x,1.5\n")
    (tmp_path / "t.md").write_text("# Title\n\n| a | b |\n|---|---|\n")
    s = Snapshot(tmp_path)
    assert render_macros('{{ cell("t", method="b", quantity="x") }}', s) == "1.5"
    assert render_macros('{{ cell("t", method="a",\n  quantity="y", fmt=".2f") }}', s) == "2.00"
    assert render_macros('{{ stat("t", "value", "mean", quantity="x") }}', s) == "1"
    assert render_macros('{{ stat("t", "value", "count", value__ge=1) }}', s) == "2"
    assert render_macros('{{ table("t") }}', s) == "| a | b |\n|---|---|"


# Experiments cheap enough to re-run at full size in the tests; their tables must equal the
# snapshot's (wall-time columns aside). The others are guarded by the golden numbers of their
# quick runs (tests/golden/), and the snapshot's manifest names the commit that made them.
RERUN = ["table1", "table2", "circle-sweep", "noise-calibration"]
WALL_TIME = {"ms_per_scan", "seconds", "median_ms_ihgr", "median_ms_milp", "ms_ihgr", "ms_milp"}


@pytest.mark.slow
def test_snapshot_equals_a_fresh_run_of_the_cheap_experiments(tmp_path):
    from experiments.paper.reproduce import run_experiments

    out = tmp_path / "fresh"
    written = run_experiments(RERUN, out_dir=out, quick=False, seed=0)
    tables = sorted(p for p in written if p.suffix == ".csv")
    assert len(tables) >= 8
    for fresh in tables:
        kept = SNAPSHOT / fresh.name
        assert kept.is_file(), f"{fresh.name} is not in the snapshot: run `trunkslam report`"
        a, b = read_tidy_csv(fresh), read_tidy_csv(kept)
        assert len(a) == len(b), f"{fresh.name}: {len(a)} rows now, {len(b)} in the snapshot"
        for i, (ra, rb) in enumerate(zip(a, b)):
            assert ra.keys() == rb.keys(), fresh.name
            for k in ra.keys() - WALL_TIME:
                va, vb = ra[k], rb[k]
                if isinstance(va, float) and isinstance(vb, float):
                    same = (math.isnan(va) and math.isnan(vb)) or math.isclose(
                        va, vb, rel_tol=1e-9, abs_tol=1e-12
                    )
                else:
                    same = va == vb
                assert same, (
                    f"{fresh.name} row {i} {k}: {va!r} now, {vb!r} in docs/results; "
                    "re-run `make reproduce` and `trunkslam report results`"
                )


def test_no_page_links_a_result_that_is_missing():
    """Figures the pages show are files of the snapshot."""
    for page in PAGES:
        for target in re.findall(r"\]\(([^)#]+\.png)\)", page.read_text()):
            assert (page.parent / target).resolve().is_file(), f"{page}: {target} missing"
