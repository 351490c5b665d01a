"""The recording a user opens is the one rerun's own archetypes make: a run recorded by
`viz.Recorder` (its rows kept as columns, `experiments.render.columns`, and sent a batch at a
time with `send_columns`) holds, entity by entity and scan by scan, exactly the rows that
logging each scan's values with `rr.log` and rerun's archetypes (`rr.Points2D`,
`rr.LineStrips2D`, ... with the values the recorder was given) makes. The reference below
draws the shapes itself one at a time (`shapes.ellipse_polyline`, `circle_polylines`) and
formats each label with an f-string, as the recorder did before its rows became columns."""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import pytest
import rerun as rr
from support import recording_rows

from experiments.eval.series import slam_panels, slam_series
from experiments.render import columns, rows, viz
from experiments.render.shapes import circle_polylines, ellipse_polyline
from experiments.sim import CycabParams, simulate_cycab_run
from slam import SlamConfig, run_slam

CFG = SlamConfig().with_(**{"features.method": "geometric", "association.method": "ihgr"})


def _ui(points: float):
    return rr.Radius.ui_points(points)


class _Archetypes:
    """A visualiser that logs every scan's rows at once with rerun's archetypes (`rr.log`),
    into the recording of `rec` (a `viz.Recorder`: its file, layout and static rows); the map's
    ellipses when the recorder logged them (`rec._map_logged`), so the rule of when is the
    recorder's and the values are checked here."""

    def __init__(self, rec: viz.Recorder) -> None:
        self.rec = rec
        self.log = rec.rec.log
        self.path: list = []
        self.truth: list = []
        self.empty: set = set()

    def _items(self, path, n, row):
        """As the recorder: a row of no item after a row of none at `path` is not logged."""
        if n == 0 and path in self.empty:
            return
        (self.empty.add if n == 0 else self.empty.discard)(path)
        self.log(path, row)

    def set_scan(self, k, stamp_s=None):
        self.rec.set_scan(k, stamp_s)
        self.rec.rec.set_time("scan", sequence=k)
        self.rec.rec.set_time("time", duration=stamp_s)

    def _pose(self, path, pose):
        x, y, th = (float(v) for v in pose)
        rot = rr.RotationAxisAngle(axis=[0, 0, 1], radians=th)
        self.log(path, rr.Transform3D(translation=[x, y, 0.0], rotation=rot))

    def log_scan(self, scan, pose=None, path="world/laser/scan"):
        self._pose("world/laser", pose)
        pts = scan.points_xy[scan.valid]
        self.log(path, rr.Points2D(pts, radii=_ui(2.0), colors=[[200, 200, 200]]))

    def log_features(self, scan, features, pose=None, path="world/laser/features"):
        pts = scan.points_xy
        strips = [pts[features.beams(a, b)] for a, b in features.segment_beams]
        kinds = viz.KIND_COLORS[np.asarray(features.segment_kind, np.int64).reshape(-1)]
        segments = rr.LineStrips2D(strips, radii=_ui(1.5), colors=kinds)
        self._items(f"{path}/segments", len(strips), segments)
        c = np.asarray(features.circle_params, float).reshape(-1, 3)
        rgb = [viz.METHOD_COLORS[features.method]]
        labels = {"labels": [f"r={r:.2f} m" for r in c[:, 2]]} if len(c) else {}
        outlines = list(circle_polylines(c))
        circles = rr.LineStrips2D(outlines, radii=_ui(1.5), colors=rgb, **labels)
        self._items(f"{path}/circles", len(c), circles)
        ends = list(np.asarray(features.line_endpoints, float).reshape(-1, 2, 2))
        lines = rr.LineStrips2D(ends, radii=_ui(2.0), colors=[[60, 120, 255]])
        self._items(f"{path}/lines", len(ends), lines)
        edges = np.asarray(features.edge_xy, float).reshape(-1, 2)
        self._items(
            f"{path}/edges", len(edges), rr.Points2D(edges, radii=_ui(4.0), colors=[[255, 40, 40]])
        )

    def log_vehicle(self, pose, cov):
        pose, cov = np.asarray(pose, float), np.asarray(cov, float)
        self.path.append(pose[:2].copy())
        self._pose("world/vehicle", pose)
        follow = rr.Transform3D(translation=[pose[0], pose[1], 0.0], scale=[1.0, -1.0, 1.0])
        self.log("world/follow", follow)
        sig = float(np.sqrt(max(cov[2, 2], 0.0)))
        label = f"heading +-{np.degrees(3 * sig):.2f} deg (3 sigma)"
        arrow = rr.Arrows2D(
            vectors=[[2.0, 0.0]],
            origins=[[0.0, 0.0]],
            radii=_ui(2.0),
            colors=[[255, 80, 80]],
            labels=[label],
        )
        self.log("world/vehicle/arrow", arrow)
        s2 = self.rec.ellipse_scale**2
        ellipse = ellipse_polyline(pose[:2], cov[:2, :2] * s2)
        red = [[255, 80, 80]]
        self.log("world/vehicle_ellipse", rr.LineStrips2D([ellipse], radii=_ui(1.0), colors=red))
        piece = np.array(self.path[-2:])
        self.log("world/path", rr.LineStrips2D([piece], radii=_ui(1.5), colors=red))
        self.rec.log_vehicle(pose, cov)

    def log_landmarks(self, xy, cov, ids, existence=None):
        xy = np.asarray(xy, float).reshape(-1, 2)
        labels = [f"L{i}" for i in ids]
        green = [[40, 200, 90]]
        self.log("world/landmarks", rr.Points2D(xy, radii=_ui(3.0), colors=green, labels=labels))
        before = self.rec._map_logged
        self.rec.log_landmarks(xy, cov, ids)
        if self.rec._map_logged is not before:  # the recorder logged the ellipses here
            self.log_ellipses(xy, np.asarray(cov, float) * self.rec.ellipse_scale**2)

    def log_ellipses(self, xy, covs):
        n = viz.ELLIPSE_POINTS - 1
        outlines = [ellipse_polyline(c, p, n=n) for c, p in zip(xy, covs.reshape(-1, 2, 2))]
        green = [[40, 200, 90]]
        self.log(
            "world/landmarks/ellipses", rr.LineStrips2D(outlines, radii=_ui(1.0), colors=green)
        )

    def close(self):
        """The map's ellipses at the last scan, when the recorder has not logged them there."""
        if self.rec._map is not None:
            _, xy, covs = self.rec._map
            self.log_ellipses(xy, np.asarray(covs, float) * self.rec.ellipse_scale**2)
            self.rec._map = None
        self.rec.close()

    def log_tentatives(self, xy):
        xy = np.asarray(xy, float).reshape(-1, 2)
        self._items(
            "world/tentative", len(xy), rr.Points2D(xy, radii=_ui(3.0), colors=[[255, 200, 0]])
        )

    def log_associations(self, from_xy, to_xy):
        a = np.asarray(from_xy, float).reshape(-1, 2)
        b = np.asarray(to_xy, float).reshape(-1, 2)
        lines = list(np.stack([a, b], axis=1))
        lines = rr.LineStrips2D(lines, radii=_ui(1.0), colors=[[0, 200, 255]])
        self._items("world/associations", len(a), lines)

    def log_truth(self, pose):
        pose = np.asarray(pose, float)
        self.truth.append(pose[:2].copy())
        white = [[255, 255, 255]]
        arrow = rr.Arrows2D(
            vectors=[[2 * np.cos(pose[2]), 2 * np.sin(pose[2])]],
            origins=[pose[:2]],
            radii=_ui(1.5),
            colors=white,
        )
        self.log("world/truth/vehicle", arrow)
        piece = np.array(self.truth[-2:])
        self.log("world/truth/path", rr.LineStrips2D([piece], radii=_ui(1.0), colors=white))
        self.rec.log_truth(pose)

    def __getattr__(self, name):
        return getattr(self.rec, name)


class _Sink:
    """A recorder that keeps nothing of the scene (its rows are the reference's): the batch
    takes the rows and drops them."""

    @staticmethod
    def quiet(rec: viz.Recorder) -> viz.Recorder:
        rec._batch.send = lambda: [t.take() for t in rec._batch.tables.values()]
        return rec


@pytest.mark.parametrize("batch", [5, 64])
def test_a_recording_holds_the_rows_rerun_archetypes_make(batch, tmp_path):
    seq = simulate_cycab_run(np.random.default_rng(7), "tree_park", CycabParams(n_scans=40))
    ours = viz.Recorder(tmp_path / "ours.rrd", series=slam_panels(True), batch_scans=batch)
    ref = _Sink.quiet(viz.Recorder(tmp_path / "ref.rrd", series=slam_panels(True)))
    for rec in (ours, ref):
        rec.log_truth_trees(seq.truth_landmarks)
    lg = run_slam(seq, CFG, visualiser=ours)
    archetypes = _Archetypes(ref)
    run_slam(seq, CFG, visualiser=archetypes)
    for rec in (ours, archetypes):
        rec.log_series(lg.scan_t, slam_series(lg, seq.truth_t, seq.truth_pose))
        rec.close()
    a = recording_rows(tmp_path / "ours.rrd", ["series/ms_per_scan"])
    b = recording_rows(tmp_path / "ref.rrd", ["series/ms_per_scan"])
    assert a.keys() == b.keys()
    scene = {"/world/laser/scan", "/world/laser/features/circles", "/world/vehicle/arrow"}
    assert scene | {"/world/landmarks/ellipses", "/world/truth/path"} <= a.keys()
    assert len(a["/world/landmarks"]) == seq.n_scans
    # some scans logged the map's ellipses, not all (viz.ELLIPSES_EVERY_S)
    assert 1 < len(a["/world/landmarks/ellipses"]) < seq.n_scans
    for entity in a:
        assert a[entity] == b[entity], entity


def test_a_table_gives_each_rows_values_with_their_offsets():
    """`columns.Table`: rows of unlike sizes and a constant, taken as one arrow array a
    component with the rows' offsets; the buffers grow past their first size and start
    afresh after a take."""
    spec = columns.Spec(
        rr.LineStrips2D,
        strips=columns.Strips(),
        colors=columns.Const(rows.color(1, 2, 3)),
        labels=columns.Texts(),
    )
    table = spec.table()
    rng = np.random.default_rng(0)
    sizes = [3, 0, 200, 1]
    pieces = [[rng.normal(size=(n + 1, 2)) for _ in range(n)] for n in sizes]
    for k, p in enumerate(pieces):
        table.add(10 + k, 0.5 * k, (columns.strips(p), [f"s{i}" for i in range(len(p))]))
    scan, time_s, cols = table.take()
    assert scan.tolist() == [10, 11, 12, 13] and time_s.tolist() == [0.0, 0.5, 1.0, 1.5]
    (d0, strips, o0), (d1, colors, o1), (d2, labels, o2) = cols
    assert [str(d) for d in (d0, d1, d2)] == [
        "LineStrips2D:strips",
        "LineStrips2D:colors",
        "LineStrips2D:labels",
    ]
    assert o0.tolist() == o2.tolist() == [0, 3, 3, 203, 204]
    assert o1.tolist() == [0, 1, 2, 3, 4] and colors.to_pylist() == [0x010203FF] * 4
    for k, p in enumerate(pieces):
        theirs = rr.LineStrips2D(p).as_component_batches()[0].as_arrow_array()
        assert strips.slice(o0[k], o0[k + 1] - o0[k]).equals(theirs)
    assert labels.slice(203, 1).to_pylist() == ["s0"]
    table.add(0, None, (columns.strips(pieces[0]), ["a", "b", "c"]))
    scan, time_s, cols = table.take()
    assert scan.tolist() == [0] and np.isnan(time_s).all() and cols[0][2].tolist() == [0, 3]
    assert cols[2][1].equals(pa.array(["a", "b", "c"]))


def test_scan_points_and_id_labels_made_at_the_flush_are_the_scans_and_labels():
    """`columns.ScanPoints`: scans of two laser geometries in one batch give each scan's
    `points_xy[valid]` (float32) in turn; `columns.IdLabels`: the labels of `rows.id_labels`,
    for ids past the table's size and for negative ids."""
    from features.types import Scan

    rng = np.random.default_rng(4)
    scans = []
    for n, a0, da in [
        (361, -np.pi / 2, np.pi / 360),
        (181, -1.0, 0.01),
        (361, -np.pi / 2, np.pi / 360),
    ]:
        ranges = rng.uniform(0.5, 30.0, n)
        ranges[rng.random(n) < 0.2] = np.nan
        scans.append(Scan(ranges, a0, da, max_range_m=25.0))
    spec = columns.Spec(rr.Points2D, positions=columns.ScanPoints(), labels=columns.IdLabels("L"))
    table = spec.table()
    ids = [np.array([0, 5, 3]), np.array([], np.int64), np.array([1000, 2])]
    for k, (scan, i) in enumerate(zip(scans, ids)):
        table.add(k, None, ((scan.ranges_m, scan.angle_min_rad, scan.angle_increment_rad), i))
    _, _, ((_, points, o), (_, labels, lo)) = table.take()
    for k, scan in enumerate(scans):
        want = rr.Points2D(scan.points_xy[scan.valid]).as_component_batches()[0].as_arrow_array()
        assert points.slice(o[k], o[k + 1] - o[k]).equals(want)
    assert labels.to_pylist() == ["L0", "L5", "L3", "L1000", "L2"] and lo.tolist() == [0, 3, 3, 5]
    assert columns.IdLabels("L")._arrow(np.array([-3, 4])).to_pylist() == ["L-3", "L4"]


def test_the_docs_state_the_batch():
    from pathlib import Path

    page = " ".join((Path(__file__).parents[2] / "docs" / "rerun.md").read_text().split())
    assert f"the rows of {viz.BATCH_SCANS} scans, or, streamed to a live viewer" in page
    assert viz.BATCH_S == 0.25 and "at most a quarter of a second" in page
