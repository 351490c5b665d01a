"""`trunkslam slam --reference-map FILE`: the map's GOSPA and OSPA against a reference in
summary.json (experiments/eval/gospa.py), and the reference file's checks."""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from experiments.cli import app
from experiments.errors import DataError
from experiments.eval.gospa import gospa, ospa
from experiments.io.reference_map import read_reference_map
from experiments.io.results import MAP_COLUMNS
from experiments.io.sequence_file import load_sequence

runner = CliRunner()


def _map_xy(out) -> np.ndarray:
    rows = (out / "map.csv").read_text().splitlines()
    head = rows[0].split(",")
    ix, iy = head.index(MAP_COLUMNS[1]), head.index(MAP_COLUMNS[2])
    return np.array([[float(r.split(",")[ix]), float(r.split(",")[iy])] for r in rows[1:]])


@pytest.mark.slow
def test_slam_scores_its_map_against_the_reference(tmp_path):
    run = tmp_path / "run.npz"
    res = runner.invoke(app, ["simulate-drive", "--scans", "60", "--seed", "2", "--out", str(run)])
    assert res.exit_code == 0, res.output
    trees = load_sequence(run).truth_landmarks[:, :2]
    ref = tmp_path / "trees.csv"
    ref.write_text("x_m,y_m\n" + "".join(f"{float(x)!r},{float(y)!r}\n" for x, y in trees))
    out = tmp_path / "out"
    res = runner.invoke(app, ["slam", str(run), "--out", str(out), "--reference-map", str(ref)])
    assert res.exit_code == 0, res.output
    assert "GOSPA" in res.output
    r = json.loads((out / "summary.json").read_text())["reference_map"]
    assert r["file"] == str(ref) and r["landmarks"] == trees.shape[0]
    xy = _map_xy(out)
    for c in (1.0, 20.0):
        g = r[f"gospa_{c:g}m"]
        want = gospa(xy, trees, p=2, c=c, alpha=2)
        # map.csv keeps 6 decimals: the summary's figure, from the full-precision map, is
        # within 1e-5 m of one computed from the file
        assert g["distance"] == pytest.approx(want.distance, abs=1e-5)
        assert g["n_missed"] == want.n_missed and g["n_false"] == want.n_false
        assert g["localisation"] + g["missed"] + g["false"] == pytest.approx(g["distance"] ** 2)
        assert r[f"ospa_{c:g}m"] == pytest.approx(ospa(xy, trees, p=2, c=c), abs=1e-5)
    # a simulated run from the truth finds trees within centimetres: at c = 1 m the missed
    # part is the trees never seen, c^2 / 2 each
    g1 = r["gospa_1m"]
    assert g1["missed"] == 0.5 * g1["n_missed"] and g1["localisation"] < 0.01 * g1["assigned"]
    # without the option, no reference part
    res = runner.invoke(app, ["slam", str(run), "--out", str(out)])
    assert "reference_map" not in json.loads((out / "summary.json").read_text())


@pytest.mark.parametrize(
    "text, message",
    [
        ("x,y\n1,2\nnan,3\n", "line 3: NaN or infinite"),
        ("1,2,3\n", "line 1: expected 2 columns"),
        ("1\n", "line 1: expected 2 columns"),
        ("x,y\n1,2\nfoo,3\n", "line 3: 'foo' is not a number"),
        ("x,y\n", "no landmark"),
        ("", "no landmark"),
        ("1,inf\n", "NaN or infinite"),
    ],
)
def test_a_bad_reference_map_is_a_clear_error(tmp_path, text, message):
    ref = tmp_path / "ref.csv"
    ref.write_text(text)
    with pytest.raises(DataError, match=message):
        read_reference_map(ref)


def test_reference_map_reads_comments_names_and_blank_lines(tmp_path):
    ref = tmp_path / "ref.csv"
    ref.write_text("# trees\nx_m, y_m\n\n1.5, -2\n3,4e1\n")
    assert read_reference_map(ref).tolist() == [[1.5, -2.0], [3.0, 40.0]]
    with pytest.raises(DataError, match="no such reference map"):
        read_reference_map(tmp_path / "none.csv")


def test_slam_refuses_a_bad_reference_map_before_running(tmp_path):
    run = tmp_path / "run.npz"
    res = runner.invoke(app, ["simulate-drive", "--scans", "10", "--seed", "2", "--out", str(run)])
    ref = tmp_path / "ref.csv"
    ref.write_text("x,y\n1,nan\n")
    out = tmp_path / "out"
    res = runner.invoke(app, ["slam", str(run), "--out", str(out), "--reference-map", str(ref)])
    assert res.exit_code == 1 and "line 2: NaN or infinite" in res.output
    assert not out.exists()
