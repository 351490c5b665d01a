"""`trunkslam report`: it refreshes the files its sources hold and keeps the snapshot's others,
says what it did, and changes nothing (snapshot and README, byte for byte) when a source, a
table, the --docs folder, the README or a page's macro is wrong."""

from __future__ import annotations

import csv
import hashlib
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from experiments.cli import app
from experiments.io.writers import read_tidy_csv
from experiments.render.refresh import RECORD, snapshot_record
from experiments.render.report import MACRO, Snapshot, render_macros

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture
def project(tmp_path) -> Path:
    """A copy of the project's documentation (pages, snapshot, site settings) and README."""
    root = tmp_path / "project"
    shutil.copytree(REPO / "docs", root / "docs")
    shutil.copy(REPO / "mkdocs.yml", root / "mkdocs.yml")
    shutil.copy(REPO / "README.md", root / "README.md")
    # the pages include files from these (examples/: the tutorial notebook the site renders)
    for included in ("datasets", "examples", "experiments"):
        os.symlink(REPO / included, root / included)
    return root


def reproduce_sized(root: Path, tmp_path: Path) -> Path:
    """A results folder with what `make reproduce` writes: the files the snapshot's main
    manifest lists, with that manifest."""
    snap = root / "docs" / "results"
    src = tmp_path / "results"
    src.mkdir()
    manifest = json.loads((snap / "manifest.json").read_text())
    for name in manifest["outputs"]:
        if (snap / name).is_file():
            shutil.copy(snap / name, src / name)
    (src / "manifest.json").write_text(json.dumps(manifest))
    return src


def tree(root: Path) -> dict[str, str]:
    """Every file under root with its digest (links to the repository's folders not
    followed): what a refused report must leave as it was."""
    found = {}
    for folder, _dirs, names in os.walk(root):
        for name in names:
            p = Path(folder) / name
            if p.is_file() and not p.is_symlink():
                found[str(p.relative_to(root))] = hashlib.sha256(p.read_bytes()).hexdigest()
    return found


def set_cells(path: Path, column: str, cells: dict[int, str]) -> None:
    """Write `cells` ({row index: text}) into `column` of the CSV table at `path`."""
    with open(path, newline="") as fh:
        rows = list(csv.reader(fh))
    k = rows[0].index(column)
    for i, text in cells.items():
        rows[i + 1][k] = text
    with open(path, "w", newline="") as fh:
        csv.writer(fh).writerows(rows)


def report(root: Path, *sources, docs=None, readme=None, pages=None):
    args = ["report", *map(str, sources)]
    args += ["--docs", str(docs or root / "docs" / "results")]
    args += ["--readme", str(readme if readme is not None else root / "README.md")]
    args += ["--pages", str(pages if pages is not None else root / "docs")]
    return CliRunner().invoke(app, args)


def test_the_committed_snapshot_has_its_record():
    """docs/results/snapshot.json lists every file of the snapshot (a file report did not
    write would make it refuse the folder)."""
    snap = REPO / "docs" / "results"
    record = json.loads((snap / RECORD).read_text())
    on_disk = sorted(p.name for p in snap.iterdir() if p.name != RECORD)
    assert sorted(record["files"]) == on_disk
    assert set(record["files"].values()) <= set(record["origins"])


def test_a_reproduce_run_replaces_its_files_and_keeps_the_others(project, tmp_path):
    snap = project / "docs" / "results"
    before = tree(snap)
    src = reproduce_sized(project, tmp_path)
    (src / "table3.csv").write_text((src / "table3.csv").read_text())  # the same numbers
    res = report(project, src)
    assert res.exit_code == 0, res.output
    after = tree(snap)
    assert set(before) <= set(after), "report removed a file it did not make"
    kept_calibration = "victoria_park_calibration.csv"
    assert after[kept_calibration] == before[kept_calibration]
    assert "kept from results_cal3: victoria-park-calibration" in res.output
    assert "kept from bench_results: bench_association.md" in res.output
    record = json.loads((snap / RECORD).read_text())
    assert record["files"]["table3.csv"] == "results"
    assert record["files"][kept_calibration] == "results_cal3"
    n_src = len([p for p in src.iterdir()])
    assert f"{n_src} replaced, 0 added" in res.output
    assert f"about {Snapshot(snap).duration()} on two cores" in " ".join(
        (project / "README.md").read_text().split()
    )
    # every page still builds from the refreshed snapshot
    for page in (project / "docs").rglob("*.md"):
        if snap not in page.parents:
            out = render_macros(page.read_text(), Snapshot(snap), str(page))
            assert not MACRO.search(out)


def test_an_empty_readme_option_means_no_readme(project, tmp_path):
    src = reproduce_sized(project, tmp_path)
    before = (project / "README.md").read_bytes()
    res = CliRunner().invoke(
        app,
        ["report", str(src), "--docs", str(project / "docs" / "results"), "--readme", ""]
        + ["--pages", str(project / "docs")],
    )
    assert res.exit_code == 0, res.output
    assert "results at a glance" not in res.output
    assert (project / "README.md").read_bytes() == before


def test_the_readmes_run_time_follows_the_new_manifest(project, tmp_path):
    src = reproduce_sized(project, tmp_path)
    manifest = json.loads((src / "manifest.json").read_text())
    manifest["seconds"] = {k: 2 * v for k, v in manifest["seconds"].items()}
    (src / "manifest.json").write_text(json.dumps(manifest))
    old = f"about {Snapshot(project / 'docs' / 'results').duration()} on two cores"
    assert old in " ".join((project / "README.md").read_text().split())
    res = report(project, src)
    assert res.exit_code == 0, res.output
    new = f"about {Snapshot(project / 'docs' / 'results').duration()} on two cores"
    assert new != old and new in " ".join((project / "README.md").read_text().split())


def test_kept_files_of_an_experiment_that_ran_again_are_named_not_refreshed(project, tmp_path):
    """A file from a run whose experiments all ran again, which none of them wrote, is kept
    and named as not refreshed (left over from an older version of an experiment)."""
    src = reproduce_sized(project, tmp_path)
    manifest = json.loads((src / "manifest.json").read_text())
    manifest["experiments"] += ["victoria-park-calibration"]
    (src / "manifest.json").write_text(json.dumps(manifest))
    res = report(project, src)
    assert res.exit_code == 0, res.output
    stale = res.output.split("not refreshed")[1].splitlines()[0]
    for name in ("victoria_park_calibration.csv", "victoria_park_ute.toml"):
        assert name in stale
    assert "loop_closure.csv" not in stale  # loop-closure did not run: kept, and fresh


def test_benchmark_tables_alone_refresh_only_themselves(project, tmp_path):
    """`make bench` then `trunkslam report bench_results`: the bench tables are replaced or
    added, the snapshot's manifest and every other file kept, a stray file skipped."""
    snap = project / "docs" / "results"
    before = tree(snap)
    bench = tmp_path / "bench_results"
    bench.mkdir()
    (bench / "bench_slam.md").write_text("Full run (a machine)\n\n| a |\n|---|\n| 1 |\n")
    (bench / "bench_new.md").write_text("New (a machine)\n\n| b |\n|---|\n| 2 |\n")
    (bench / "notes.md").write_text("not a benchmark table\n")
    res = report(project, bench)
    assert res.exit_code == 0, res.output
    after = tree(snap)
    assert after["bench_slam.md"] != before["bench_slam.md"]
    assert "bench_new.md" in after and "notes.md" not in after
    assert after["manifest.json"] == before["manifest.json"]
    changed = {n for n in before if after[n] != before[n]}
    assert changed == {"bench_slam.md", "snapshot.json"}
    assert "1 replaced, 1 added" in res.output and "skipped" in res.output
    record = json.loads((snap / RECORD).read_text())
    assert record["files"]["bench_new.md"] == "bench_results"


def test_a_second_report_keeps_what_the_first_one_kept(project, tmp_path):
    src = reproduce_sized(project, tmp_path)
    assert report(project, src).exit_code == 0
    snap = project / "docs" / "results"
    first = tree(snap)
    res = report(project, src)
    assert res.exit_code == 0, res.output
    assert tree(snap) == first
    assert "results at a glance unchanged" in res.output


def refused(project: Path, *sources, expect: str, **kw) -> None:
    before = tree(project)
    res = report(project, *sources, **kw)
    assert res.exit_code != 0, res.output
    assert expect in res.output, res.output
    assert "Traceback" not in res.output
    assert tree(project) == before, "a refused report changed a file"


def test_a_bad_source_changes_nothing(project, tmp_path):
    refused(project, tmp_path / "missing", expect="no such folder")
    (tmp_path / "empty").mkdir()
    refused(project, tmp_path / "empty", expect="not a `trunkslam reproduce` folder")
    (tmp_path / "plain.txt").write_text("x")
    refused(project, tmp_path / "plain.txt", expect="not a folder")
    slam_out = tmp_path / "slam_out"
    slam_out.mkdir()
    (slam_out / "summary.json").write_text("{}")
    (slam_out / "manifest.json").write_text(
        json.dumps({"command": "trunkslam slam", "outputs": ["summary.json"]})
    )
    refused(project, slam_out, expect="not of `trunkslam reproduce`")
    src = reproduce_sized(project, tmp_path)
    (tmp_path / "no_tables").mkdir()
    refused(project, src, tmp_path / "no_tables", expect="nor a folder of benchmark tables")
    (tmp_path / "notes").mkdir()
    (tmp_path / "notes" / "chapter1.md").write_text("mine\n")
    refused(project, tmp_path / "notes", expect="nor a folder of benchmark tables")


def test_a_bad_readme_or_docs_folder_changes_nothing(project, tmp_path):
    src = reproduce_sized(project, tmp_path)
    refused(project, src, readme=project / "missing.md", expect="--readme")
    plain = project / "plain.md"
    plain.write_text("# no glance block\n")
    refused(project, src, readme=plain, expect="no results-at-a-glance block")
    thesis = project / "thesis"
    thesis.mkdir()
    for name in ("chapter1.md", "data.csv", "pyproject.toml", "refs.json"):
        (thesis / name).write_text("mine\n")
    refused(project, src, docs=thesis, expect="holds chapter1.md")
    refused(project, src, docs=project, expect="not a snapshot `trunkslam report` made")
    (project / "docs" / "results" / "notes.md").write_text("mine\n")
    refused(project, src, expect="holds notes.md, which `trunkslam report` did not write")


def test_a_link_in_the_snapshot_or_as_the_readme_is_refused(project, tmp_path):
    src = reproduce_sized(project, tmp_path)
    victim = tmp_path / "thesis.tex"
    victim.write_text("mine\n")
    os.symlink(victim, project / "docs" / "results" / "table9.csv")
    refused(project, src, expect="table9.csv")
    (project / "docs" / "results" / "table9.csv").unlink()
    readme_link = project / "README_link.md"
    os.symlink(project / "README.md", readme_link)
    refused(project, src, readme=readme_link, expect="symbolic link")
    assert victim.read_text() == "mine\n"


@pytest.mark.parametrize(
    ("table", "column", "cell", "expect"),
    [
        ("table3", "value", "garbage", "is not a number"),
        ("table1_ce", "value", "x1", "is not a number"),
        ("victoria_park", "landmarks", "12.5", "is not a whole number"),
        ("consistency", "nees_in_bounds", "nan-ish", "is not a number"),
    ],
)
def test_a_corrupt_cell_changes_nothing(project, tmp_path, table, column, cell, expect):
    src = reproduce_sized(project, tmp_path)
    path = src / f"{table}.csv"
    if not path.is_file():
        shutil.copy(project / "docs" / "results" / path.name, path)
    set_cells(path, column, {0: cell})
    refused(project, src, expect=f"{table}.csv line 2, column {column}")
    assert expect in report(project, src).output


def test_a_ragged_or_binary_table_changes_nothing(project, tmp_path):
    src = reproduce_sized(project, tmp_path)
    path = src / "table4.csv"
    path.write_text(path.read_text() + "only,two\n")
    refused(project, src, expect="table4.csv line")
    path.write_bytes(b"\xff\xfe\x00garbage")
    refused(project, src, expect="not a text table")


def test_a_missing_count_prints_n_a_in_the_glance(project, tmp_path):
    """An empty count cell (NaN) is a missing figure: the glance prints n/a, no traceback."""
    src = reproduce_sized(project, tmp_path)
    shutil.copy(project / "docs" / "results" / "loop_closure.csv", src / "loop_closure.csv")
    path = src / "loop_closure.csv"
    set_cells(path, "false_closures", dict.fromkeys(range(len(read_tidy_csv(path))), ""))
    res = report(project, src)
    assert res.exit_code == 0, res.output
    assert "n/a / n/a in" in (project / "README.md").read_text()


def test_results_a_page_needs_are_refused_with_the_page_named(project, tmp_path):
    """A source whose table lacks a row a page quotes: refused (the site would not build),
    naming the page; the snapshot and README as they were."""
    src = reproduce_sized(project, tmp_path)
    path = src / "table3.csv"
    lines = path.read_text().splitlines()
    path.write_text("\n".join(lines[:2]) + "\n")
    refused(project, src, expect="a macro would not resolve")
    assert "table3.csv: 0 rows match" in report(project, src).output
    assert "--quick" not in report(project, src).output
    manifest = json.loads((src / "manifest.json").read_text())
    (src / "manifest.json").write_text(json.dumps({**manifest, "quick": True}))
    assert "these are `reproduce --quick` results" in report(project, src).output


def test_snapshot_record_reads_origins_from_the_manifests(tmp_path):
    snap = tmp_path / "snap"
    shutil.copytree(REPO / "docs" / "results", snap)
    (snap / RECORD).unlink()
    record = snapshot_record(snap)
    assert record["files"]["victoria_park_ute.toml"] == "results_cal3"
    assert record["files"]["bench_slam.md"] == "bench_results"
    assert record["files"]["manifest.json"] == "results"
    assert record["origins"]["results_cal3"]["experiments"] == ["victoria-park-calibration"]


@pytest.mark.slow
def test_report_then_the_docs_build(project, tmp_path):
    """`make reproduce`-sized results through `report`, then `mkdocs build --strict`."""
    src = reproduce_sized(project, tmp_path)
    res = report(project, src)
    assert res.exit_code == 0, res.output
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}
    build = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--quiet"],
        cwd=project,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert build.returncode == 0, build.stderr[-3000:]
    assert (project / "build" / "site" / "index.html").is_file()
