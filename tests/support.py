"""Helpers shared by test modules (tests/ is on pytest's pythonpath)."""

from __future__ import annotations

import hashlib
import math
from pathlib import Path

import numpy as np

from slam import Sequence
from slam.sequence import OPTIONAL, REQUIRED

N, B = 5, 7


def full_kwargs() -> dict:
    """Every field of a small simulated-looking run, all valid."""
    rng = np.random.default_rng(1)
    ranges = rng.uniform(1.0, 30.0, (N, B))
    ranges[0, 2] = np.nan
    ranges[3, :] = np.nan  # a scan with no return at all
    labels = rng.integers(-1, 6, (N, B))
    labels[1, 1] = -2  # mixed return
    return dict(
        scan_t=np.arange(N) * 0.2 + 10.0,
        scan_ranges=ranges,
        scan_angle_min=-math.pi / 2,
        scan_angle_increment=math.pi / 360,
        laser_pose=[3.78, 0.5, 0.0],
        scan_max_range=50.0,
        odo_t=np.arange(12) * 0.1 + 10.0,
        odo_speed=np.linspace(0.0, 2.0, 12),
        odo_steer=np.linspace(-0.1, 0.1, 12),
        vehicle={"model": "ackermann", "wheelbase_m": 2.83, "encoder_offset_m": 0.76},
        gps_t=np.array([10.0, 10.5, 11.0]),
        gps_xy=np.array([[0.0, 1.0], [1.0, 1.5], [2.0, 2.0]]),
        gps_pose=[1.0, 0.0, 0.0],
        gps_origin=[-33.89, 151.19, 12.0],
        truth_t=np.arange(N) * 0.2 + 10.0,
        truth_pose=rng.normal(size=(N, 3)),
        truth_landmarks=np.array([[5.0, 1.0, 0.2], [8.0, -2.0, 0.35]]),
        scan_labels=labels,
        name="unit test run",
        det_scan=np.array([0, 0, 2, 4]),
        det_range=np.array([5.0, 7.5, 6.2, 12.0]),
        det_bearing=np.array([-0.4, 0.3, 0.0, 1.2]),
        det_radius=np.array([0.2, 0.3, np.nan, 0.15]),
        det_cov=np.array([np.diag([0.01, 1e-4])] * 4),
        det_method="bailey",
    )


def assert_same(a: Sequence, b: Sequence) -> None:
    for name in (*REQUIRED, *OPTIONAL):
        va, vb = getattr(a, name), getattr(b, name)
        if isinstance(va, np.ndarray):
            assert isinstance(vb, np.ndarray), name
            assert va.dtype == vb.dtype and va.shape == vb.shape, name
            np.testing.assert_array_equal(va, vb, err_msg=name)  # NaN == NaN here
        else:
            assert va == vb, name


def num_jac(f, x, eps=1e-6) -> np.ndarray:
    """Central-difference Jacobian of f at x (the oracle of every analytic Jacobian)."""
    x = np.asarray(x, float)
    cols = []
    for i in range(x.size):
        d = np.zeros_like(x)
        d[i] = eps
        cols.append((f(x + d) - f(x - d)) / (2 * eps))
    return np.stack(cols, axis=-1)


def assert_outputs(folder, names, min_bytes: int = 1) -> None:
    """Every file in `names` exists in `folder` with at least `min_bytes` bytes."""
    for name in names:
        p = folder / name
        assert p.exists() and p.stat().st_size >= min_bytes, name


def simulated_scan_file(tmp_path, scene: str = "test_yard"):
    """`trunkslam simulate SCENE --pose 0,0,0` into tmp_path/scan.npz; returns the path."""
    from typer.testing import CliRunner

    from experiments.cli import app

    path = tmp_path / "scan.npz"
    res = CliRunner().invoke(app, ["simulate", scene, "--pose", "0,0,0", "--out", str(path)])
    assert res.exit_code == 0, res.output
    return path


def quick_reproduce(tmp_path_factory, name: str, seed: int):
    """`trunkslam reproduce NAME --quick --seed SEED` into a new temporary folder; returns it."""
    from experiments.paper.reproduce import run_experiments

    out = tmp_path_factory.mktemp(name)
    run_experiments([name], out, quick=True, seed=seed)
    return out


def read_recording(path) -> dict:
    """What a `.rrd` file holds, read back with the rerun SDK's reader (`rerun.chunk.RrdReader`):
    entity paths (without the leading /), timelines, and the views of the blueprint the file
    carries as (class, origin, contents, name) with the origins and contents without the
    leading /; class "2D", "3D" or "TimeSeries"."""
    from rerun.chunk import RrdReader

    reader = RrdReader(path)
    schema = reader.store().schema()
    entities = {str(e).lstrip("/") for e in schema.entity_paths()}
    timelines = {str(i).removeprefix("Index(timeline:").rstrip(")") for i in schema.index_columns()}
    views, contents = {}, {}
    for store in reader.blueprints():
        for chunk in reader.store(store=store).stream().to_chunks():
            d = chunk.to_record_batch().to_pydict()
            path = str(chunk.entity_path).lstrip("/")
            if "ViewBlueprint:class_identifier" in d:
                views[path] = (
                    d["ViewBlueprint:class_identifier"][-1][0],
                    d["ViewBlueprint:space_origin"][-1][0].lstrip("/"),
                    d["ViewBlueprint:display_name"][-1][0],
                )
            if "ViewContents:query" in d:
                contents[path.removesuffix("/ViewContents")] = d["ViewContents:query"][-1]
    return {
        "entities": entities,
        "timelines": timelines,
        "blueprints": len(reader.blueprints()),
        "views": [(c, o, contents.get(k, []), n) for k, (c, o, n) in views.items()],
    }


# the result CSVs whose Markdown is not a pivot of them: the optimality study's CSV holds every
# instance, its Markdown a summary (medians, fractions) of them
NOT_PIVOTED = {"association_optimality.csv"}


def _md_tables(md_path):
    """(csv name, pivot spec, header cells, body rows of cells) of every table in a Markdown
    result file that `write_tidy_table` marked as the pivot of a CSV."""
    import json

    from experiments.io.writers import PIVOT_MARK

    lines = md_path.read_text().splitlines()
    out = []
    for i, line in enumerate(lines):
        if not line.startswith(PIVOT_MARK):
            continue
        name, spec = line[len(PIVOT_MARK) :].removesuffix(" -->").split(": ", 1)
        table = []
        for row in lines[i + 1 :]:
            if not row.startswith("|"):
                break
            table.append([c.strip() for c in row.strip()[1:-1].split(" | ")])
        out.append((name, json.loads(spec), table[0], table[2:]))
    return out


def assert_tidy_tables(folder) -> set[str]:
    """Every result CSV in `folder` is tidy and its Markdown tables are its pivots: read with
    `csv.DictReader`, every column is shown in a pivot (index, columns, values; a wide table
    may be split into several narrow pivots of the same CSV, `write_tidy_table(parts=...)`,
    which together show every column), each observation (the index and column fields) is
    there once, every value cell is a number or empty, and pivoting the CSV's records gives
    exactly each Markdown table's cells. Returns the names of the CSVs checked; fails on a CSV
    that no Markdown table is the pivot of."""
    import csv

    from experiments.io.writers import parse_value, pivot_cells

    checked = set()
    shown: dict[str, set] = {}  # CSV -> the columns its pivots show
    all_fields: dict[str, list] = {}
    for md in sorted(folder.glob("*.md")):
        for name, spec, header, body in _md_tables(md):
            with (folder / name).open(newline="") as fh:
                reader = csv.DictReader(fh)
                raw = list(reader)
                fields = reader.fieldnames
            keys = spec["index"] + spec["columns"]
            assert len(fields) == len(set(fields)), name
            assert set(keys) | set(spec["values"]) <= set(fields), (name, fields, spec)
            shown.setdefault(name, set()).update(keys, spec["values"])
            all_fields[name] = fields
            ids = [tuple(r[k] for k in keys) for r in raw]
            assert len(ids) == len(set(ids)), f"{name}: an observation appears twice"
            assert all(r[k] != "" for r in raw for k in keys), f"{name}: an empty identifier"
            for r in raw:
                for v in spec["values"]:
                    assert r[v] == "" or isinstance(parse_value(r[v]), (int, float)), (name, v)
            records = [{k: parse_value(v) for k, v in r.items()} for r in raw]
            cells = pivot_cells(records, spec["index"], spec["columns"], spec["values"])
            assert len(header) == len(cells[0]), name
            assert cells == body, name
            checked.add(name)
    for name, cols in shown.items():
        assert cols == set(all_fields[name]), f"{name}: columns in no pivot: {all_fields[name]}"
    stray = {p.name for p in folder.glob("*.csv")} - checked - NOT_PIVOTED
    assert not stray, f"CSVs with no Markdown pivot: {stray}"
    return checked


# columns rerun fills differently in every file: row ids, the time a row was logged
VOLATILE_RECORDING_COLUMNS = ("rerun.controls.RowId", "log_time", "log_tick")


def recording_rows(path, skip_entities=()) -> dict[str, list[str]]:
    """Everything a `.rrd` file's recording holds (its main store, not the blueprint), as rows
    per entity path: every column but the volatile ones (row ids, log times, the recording's
    start time), in a canonical order (rerun groups rows into chunks as its batcher flushes,
    which differs between runs). Two recordings of the same content compare equal; entities in
    `skip_entities` (e.g. series of wall times) are left out."""
    from rerun.chunk import RrdReader

    rows: dict[str, list[str]] = {}
    for chunk in RrdReader(path).store().stream().to_chunks():
        entity = str(chunk.entity_path)
        if entity.lstrip("/") in skip_entities:
            continue
        data = chunk.to_record_batch().to_pydict()
        cols = sorted(
            k for k in data if k not in VOLATILE_RECORDING_COLUMNS and not k.endswith("start_time")
        )
        for i in range(chunk.num_rows):
            rows.setdefault(entity, []).append(repr([(k, data[k][i]) for k in cols]))
    return {k: sorted(v) for k, v in rows.items()}


def two_landmarks_with_cross_term(cross: float):
    """(z, z_hat, H, P) of two measurements near two landmarks whose own 2 x 2 blocks of P are
    0.1 I and whose cross term P[3, 5] is `cross`: with 0.5 the joint block is not positive
    semi-definite (correlation 5) though each landmark's block is; with 0.05 it is valid."""
    P = np.eye(7) * 0.1
    P[3, 5] = P[5, 3] = cross
    H = np.zeros((2, 2, 7))
    H[0, :, 3:5] = np.eye(2)
    H[1, :, 5:7] = np.eye(2)
    z_hat = np.array([[5.0, 0.1], [5.2, 0.12]])
    z = np.array([[5.1, 0.11], [5.15, 0.115]])
    return z, z_hat, H, P


# ---- result folders ------------------------------------------------------------------------


def snapshot(folder: Path) -> dict[str, str]:
    """{relative path: sha256} of every file under folder (hidden ones too)."""
    return {
        str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(folder.rglob("*"))
        if p.is_file()
    }


def leftovers(folder: Path) -> list[str]:
    """Temporary folders, files or locks of `folder` left beside it or in it."""
    beside = [p.name for p in folder.parent.glob(f".{folder.name}.*")]
    inside = [p.name for p in folder.glob(".*")] if folder.is_dir() else []
    return beside + inside


def invoke(*args) -> None:
    """`trunkslam ARGS` in this process (typer's runner); it must succeed."""
    from typer.testing import CliRunner

    from experiments.cli import app

    res = CliRunner().invoke(app, [str(a) for a in args])
    assert res.exit_code == 0, res.output
