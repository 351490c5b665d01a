"""`trunkslam export-map` (experiments/io/map_export.py): a run's map as GeoJSON or CSV, the
frame named, covariance ellipses as polygons."""

from __future__ import annotations

import csv
import dataclasses
import json
import math
import os

import numpy as np
import pytest
from typer.testing import CliRunner

from experiments.cli import app
from experiments.errors import DataError
from experiments.io.map_export import ellipse_polygon, read_map_csv, wgs84_from_local
from experiments.io.results import MAP_COLUMNS
from experiments.io.rosbag import local_metres
from experiments.io.sequence_file import load_sequence, save_sequence

runner = CliRunner()


def test_ellipse_polygon_lies_on_the_confidence_contour():
    rng = np.random.default_rng(3)
    for _ in range(20):
        A = rng.normal(size=(2, 2))
        C = A @ A.T + 0.01 * np.eye(2)
        c = rng.normal(size=2) * 10
        for q in (0.5, 0.95, 0.99):
            ring = ellipse_polygon(c, C, q, vertices=64)
            assert ring.shape == (65, 2) and np.array_equal(ring[0], ring[-1])
            d = ring - c
            m2 = np.einsum("ki,ij,kj->k", d, np.linalg.inv(C), d)
            # every vertex on {d^T C^-1 d = chi2_2(q) = -2 ln(1 - q)}, to rounding
            assert np.allclose(m2, -2.0 * math.log(1.0 - q), rtol=1e-9)
            x, y = ring[:, 0], ring[:, 1]
            signed = 0.5 * np.sum(x[:-1] * y[1:] - x[1:] * y[:-1])
            # counter-clockwise (RFC 7946's exterior ring); a 64-gon inscribed in the ellipse
            # has area pi a b sin(2 pi / 64) / (2 pi / 64)
            s = -2.0 * math.log(1.0 - q)
            area = math.pi * s * math.sqrt(np.linalg.det(C))
            assert signed == pytest.approx(area * math.sin(2 * math.pi / 64) / (2 * math.pi / 64))


def test_wgs84_is_the_exact_inverse_of_the_rosbag_projection():
    rng = np.random.default_rng(4)
    for lat0, lon0, h0 in ((48.1, 11.5, 520.0), (-33.89, 151.19, 0.0), (60.0, 179.99, 10.0)):
        xy = rng.uniform(-2000.0, 2000.0, (50, 2))
        lonlat = wgs84_from_local(xy, (lat0, lon0, h0))
        back = local_metres(lonlat[:, 1], lonlat[:, 0], lat0, lon0, h0)
        assert np.abs(back - xy).max() < 1e-8  # metres: rounding of degrees near 1e-14


def _write_map(path, rows):
    path.write_text(",".join(MAP_COLUMNS) + "\n" + "".join(r + "\n" for r in rows))


@pytest.mark.parametrize(
    "rows, message",
    [
        (["0,1,2,,nan,0,1,0,3"], "line 2: NaN"),
        (["0,1,2,,1,5,1,0,3"], "line 2: the covariance is not positive semi-definite"),
        (["0,1,2,,1,0,1,0"], "line 2: 8 cells"),
        (["0,1,x,,1,0,1,0,3"], "line 2: could not convert"),
    ],
)
def test_a_bad_map_file_is_a_clear_error(tmp_path, rows, message):
    path = tmp_path / "map.csv"
    _write_map(path, rows)
    with pytest.raises(DataError, match=message):
        read_map_csv(path)
    path.write_text("id,x,y\n")
    with pytest.raises(DataError, match="line 1: expected the columns"):
        read_map_csv(path)


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("map_run")
    seq = tmp / "run.npz"
    res = runner.invoke(app, ["simulate-drive", "--scans", "60", "--seed", "2", "--out", str(seq)])
    assert res.exit_code == 0, res.output
    out = tmp / "out"
    res = runner.invoke(app, ["slam", str(seq), "--out", str(out)])
    assert res.exit_code == 0, res.output
    return out


@pytest.mark.slow
def test_geojson_and_csv_hold_the_map_and_its_ellipses(run_dir, tmp_path):
    m = read_map_csv(run_dir / "map.csv")
    path = tmp_path / "map.geojson"
    res = runner.invoke(app, ["export-map", str(run_dir), "--out", str(path), "--vertices", "12"])
    assert res.exit_code == 0, res.output
    doc = json.loads(path.read_text())
    assert doc["type"] == "FeatureCollection" and doc["frame"]["name"] == "local"
    points = [f for f in doc["features"] if f["geometry"]["type"] == "Point"]
    rings = [f for f in doc["features"] if f["geometry"]["type"] == "Polygon"]
    assert len(points) == len(rings) == m.id.size > 3
    for j, (p, r) in enumerate(zip(points, rings)):
        assert p["properties"]["id"] == r["properties"]["id"] == m.id[j]
        assert p["geometry"]["coordinates"] == pytest.approx(m.xy[j].tolist(), abs=1e-9)
        ring = np.array(r["geometry"]["coordinates"][0])
        assert ring.shape == (13, 2)
        want = ellipse_polygon(m.xy[j], m.cov[j], 0.95, 12)
        assert np.abs(ring - want).max() < 1e-9
    path = tmp_path / "map.csv"
    res = runner.invoke(
        app, ["export-map", str(run_dir), "--format", "csv", "--out", str(path),
              "--confidence", "0.5"]
    )  # fmt: skip
    assert res.exit_code == 0, res.output
    rows = list(csv.DictReader(path.open()))
    assert len(rows) == m.id.size and "lon_deg" not in rows[0]
    for j, r in enumerate(rows):
        C = m.cov[j]
        a, b = float(r["semi_major_m"]), float(r["semi_minor_m"])
        # the axes' product: the ellipse's area / pi = chi2_2(0.5) sqrt(det C)
        assert a * b == pytest.approx(-2 * math.log(0.5) * math.sqrt(np.linalg.det(C)), rel=1e-5)
        assert a >= b and float(r["confidence"]) == 0.5


@pytest.fixture(scope="module")
def gps_run(run_dir, tmp_path_factory):
    """The same drive without its truth, so that the run starts from GPS, and with a GNSS
    origin as the rosbag converter keeps one."""
    tmp = tmp_path_factory.mktemp("gps_run")
    seq = load_sequence(json.loads((run_dir / "summary.json").read_text())["input"])
    blind = dataclasses.replace(
        seq, truth_t=None, truth_pose=None, truth_landmarks=None, scan_labels=None,
        gps_origin=np.array(ORIGIN),
    )  # fmt: skip
    save_sequence(blind, tmp / "gps.npz")
    assert load_sequence(tmp / "gps.npz").gps_origin.tolist() == list(ORIGIN)
    out = tmp / "out"
    res = runner.invoke(app, ["slam", str(tmp / "gps.npz"), "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert json.loads((out / "summary.json").read_text())["start"] == "gps"
    return out


ORIGIN = (48.1, 11.5, 520.0)


@pytest.mark.slow
def test_wgs84_only_for_a_run_that_started_from_gps(run_dir, gps_run, tmp_path):
    res = runner.invoke(app, ["export-map", str(run_dir), "--frame", "wgs84", "--origin",
                              "48.1,11.5", "--out", str(tmp_path / "w.geojson")])  # fmt: skip
    assert res.exit_code == 1 and "started from 'truth', not from GPS" in res.output
    # the sequence's gps_origin
    path = tmp_path / "w.geojson"
    res = runner.invoke(app, ["export-map", str(gps_run), "--frame", "wgs84", "--out", str(path)])
    assert res.exit_code == 0, res.output
    doc = json.loads(path.read_text())
    assert doc["frame"]["name"] == "wgs84"
    assert doc["frame"]["gnss_origin_lat_lon_alt"] == list(ORIGIN)
    m = read_map_csv(gps_run / "map.csv")
    lonlat = np.array([f["geometry"]["coordinates"] for f in doc["features"][::2]])
    back = local_metres(lonlat[:, 1], lonlat[:, 0], *ORIGIN)
    assert np.abs(back - m.xy).max() < 1e-4  # 1e-10 degrees written: about 1e-5 m
    # --origin instead of the sequence's
    args = ["--format", "csv", "--frame", "wgs84", "--origin", "-33.9,151.2"]
    res = runner.invoke(app, ["export-map", str(gps_run), *args, "--out", str(tmp_path / "w.csv")])
    rows = list(csv.DictReader((tmp_path / "w.csv").open()))
    assert float(rows[0]["lat_deg"]) == pytest.approx(-33.9, abs=0.01)
    res = runner.invoke(app, ["export-map", str(gps_run), "--origin", "48,11",
                              "--out", str(tmp_path / "b.geojson")])  # fmt: skip
    assert res.exit_code == 1 and "give --frame wgs84 with it" in res.output
    for bad in ("91,0", "48,11,x", "48"):
        res = runner.invoke(app, ["export-map", str(gps_run), "--frame", "wgs84", "--origin",
                                  bad, "--out", str(tmp_path / "b.geojson")])  # fmt: skip
        assert res.exit_code in (1, 2) and "origin" in res.output, bad


@pytest.mark.slow
def test_export_map_refuses_bad_places_and_values(run_dir, tmp_path):
    res = runner.invoke(app, ["export-map", str(run_dir), "--confidence", "1",
                              "--out", str(tmp_path / "m.geojson")])  # fmt: skip
    assert res.exit_code == 1 and "confidence" in res.output
    res = runner.invoke(app, ["export-map", str(run_dir), "--smoothed",
                              "--out", str(tmp_path / "m.geojson")])  # fmt: skip
    assert res.exit_code == 1 and "map_smoothed.csv: no such map file" in res.output
    res = runner.invoke(app, ["export-map", str(run_dir), "--out", str(run_dir / "m.geojson")])
    assert res.exit_code == 1 and "inside the input folder" in res.output
    target = tmp_path / "t.geojson"
    target.write_text("keep")
    os.symlink(target, tmp_path / "l.geojson")
    res = runner.invoke(app, ["export-map", str(run_dir), "--out", str(tmp_path / "l.geojson")])
    assert res.exit_code == 1 and "symbolic link" in res.output and target.read_text() == "keep"
    res = runner.invoke(app, ["export-map", str(run_dir), "--format", "kml"])
    assert res.exit_code == 2


def test_a_sequence_checks_its_gnss_origin():
    from support import full_kwargs

    from slam import Sequence, SlamError

    kw = full_kwargs()
    assert Sequence(**kw).gps_origin.tolist() == [-33.89, 151.19, 12.0]
    for bad, message in (
        ([90.0, 0.0, 0.0], "latitude within"),
        ([0.0, 181.0, 0.0], "longitude within"),
        ([0.0, 0.0], "expected shape"),
        ([0.0, np.nan, 0.0], "gps_origin"),
    ):
        with pytest.raises(SlamError, match=message):
            Sequence(**{**kw, "gps_origin": bad})
    no_gps = {**kw, "gps_t": None, "gps_xy": None, "gps_pose": None}
    with pytest.raises(SlamError, match="no gps_t"):
        Sequence(**no_gps)
