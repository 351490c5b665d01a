"""The vehicle's entities are kept as one record a scan (`viz._VehicleRows`) and made into
their rows at the flush: with decimation (the path's pieces then span the skipped scans), over
several batches, and before any scan (logged at once), the rows are those of the rule: the
pose, the heading's 3-sigma label, the position's ellipse, and the path from the last logged
point to this one."""

from __future__ import annotations

import numpy as np
from rerun.chunk import RrdReader

from experiments.render import viz
from experiments.render.shapes import ellipse_polyline


def _rows(path, entity: str, component: str) -> dict:
    """{scan (None: no scan): the component's value as a Python list} of one entity."""
    out = {}
    for chunk in RrdReader(path).store().stream().to_chunks():
        if str(chunk.entity_path) != entity:
            continue
        rb = chunk.to_record_batch()
        timed = "scan" in rb.schema.names
        scans = rb.column("scan").to_pylist() if timed else [None] * rb.num_rows
        for i, k in enumerate(scans):
            out[k] = rb.column(component)[i].as_py()
    return out


def test_vehicle_rows_with_decimation_over_batches(tmp_path):
    rng = np.random.default_rng(2)
    n, every, scale = 23, 3, 10.0
    poses = np.cumsum(rng.normal(size=(n, 3)), axis=0)
    a = rng.normal(size=(n, 3, 3))
    covs = a @ a.transpose(0, 2, 1)
    path = tmp_path / "v.rrd"
    with viz.Recorder(path, decimate=every, ellipse_scale=scale, batch_scans=4) as rec:
        for k in range(n):
            rec.set_scan(k, 0.1 * k)
            rec.log_vehicle(poses[k], covs[k])
    logged = list(range(0, n, every))
    pieces = _rows(path, "/world/path", "LineStrips2D:strips")
    pose = _rows(path, "/world/vehicle", "Transform3D:translation")
    arrow = _rows(path, "/world/vehicle/arrow", "Arrows2D:labels")
    ellipse = _rows(path, "/world/vehicle_ellipse", "LineStrips2D:strips")
    assert sorted(pieces) == sorted(pose) == sorted(arrow) == sorted(ellipse) == logged
    f32 = np.float32
    for i, k in enumerate(logged):
        start = logged[i - 1] if i else 0  # from the last logged point, the skipped ones too
        (piece,) = pieces[k]
        assert np.array_equal(np.array(piece, f32), poses[start : k + 1, :2].astype(f32))
        assert pose[k] == [[float(f32(poses[k, 0])), float(f32(poses[k, 1])), 0.0]]
        sigma = np.sqrt(max(covs[k, 2, 2], 0.0))
        assert arrow[k] == [f"heading +-{np.degrees(3 * sigma):.2f} deg (3 sigma)"]
        want = ellipse_polyline(poses[k, :2], covs[k, :2, :2] * scale**2).astype(f32)
        assert np.array_equal(np.array(ellipse[k][0], f32), want)


def test_vehicle_before_any_scan_is_logged_at_once(tmp_path):
    path = tmp_path / "v.rrd"
    with viz.Recorder(path) as rec:
        rec.log_vehicle(np.array([1.0, 2.0, 0.5]), np.eye(3))
    (piece,) = _rows(path, "/world/path", "LineStrips2D:strips").values()
    assert piece == [[[1.0, 2.0]]]
    assert list(_rows(path, "/world/vehicle", "Transform3D:translation")) == [None]
