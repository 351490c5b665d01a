"""Rerun inspection: our dataclasses as rerun entities on the timelines `scan` (index) and
`time` (the scan's time, s, when known). The only module that imports rerun.

Every recording carries its layout (a blueprint, `rerun.blueprint`), chosen by its kind:

- "slam": a map that follows the vehicle (north up, 50 m across) beside a whole-map tab, the
  scan in the laser frame, and time series panels (`experiments.eval.series`: pose error with
  3-sigma bounds when there is truth, NIS with its 95% bounds, innovations with 2-sigma bounds,
  map size, ms a scan);
- "features": the scans in the laser frame (`laser/scan`, `laser/features/<method>`), and
  circles per scan;
- "circles": the simulated pillar court in the world frame (one scan per position, every
  method's circles, the true pillars) and the figure scans.

Entities. A frame entity carries a 2D pose as a rerun transform; its children are in its frame.
  world/laser                the laser's world pose (frame entity)
  world/laser/scan           scan points (grey), laser frame
  world/laser/features/...   segments (strips coloured by kind: line blue, circle brown,
                             clutter orange), circles (outline coloured by method, radius
                             label), lines, edges (red); the hues of the PNG figures
  world/truth/...            simulated truth: trees (white dots, true outlines) or pillars,
                             true pose (`vehicle`) and path (`path`)
SLAM runs (slam.run_slam's visualiser interface):
  world/vehicle              estimated pose (frame entity) with its arrow (`world/vehicle/arrow`)
  world/vehicle_ellipse      95% position ellipse, drawn `ellipse_scale` times its size
  world/path                 estimated path so far: a piece a scan (the points since the last
                             logged scan), drawn whole up to the time cursor (a trail: the map
                             views' visible time range on it, `TRAILS`); so is world/truth/path
  world/follow               the vehicle's position without its heading, y mirrored (the
                             following map view's origin; rerun draws 2D views y down)
  .../y_up                   static y mirror under each view's frame: every view reads y up
  world/landmarks            map landmarks: centres, ids; `ellipses`: 95% ellipses, scaled,
                             logged when the map's landmarks change, every ELLIPSES_EVERY_S of
                             the sequence's time and at the last scan
  world/tentative            tentative features (not yet in the map)
  world/associations         lines from each associated measurement to its landmark
  series/...                 the time series
"""

from __future__ import annotations

import contextlib
import errno
import functools
import logging
import os
import shutil
import tempfile
import time
from pathlib import Path

try:
    import resource
except ImportError:  # pragma: no cover  (not POSIX)
    resource = None
import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from experiments.errors import ConfigError, DataError, WriteError
from experiments.io.outputs import check_output_file
from experiments.io.writers import interruption_point
from experiments.render import columns, rows
from experiments.render.null_recorder import NullRecorder
from experiments.render.rerun_sink import Viewer, viewer_program
from experiments.render.shapes import circle_polylines
from features.types import Features, Scan
from slam import se2

__all__ = [
    "KINDS",
    "LiveRecorder",
    "RECORDING_MIN_FREE_BYTES",
    "MemoryRecorder",
    "NullRecorder",
    "Recorder",
    "blueprint",
    "open_recording",
    "writer_stopped",
]

KINDS = ("slam", "features", "circles")
# A recording is not started on a file system with less free space than this (a tree-park
# drive's recording is 10-20 kB a scan, a decimated Victoria Park run's a few MB; the margin is
# for the rest of the command's outputs), and is stopped when its next batch is due (the file
# grows only then) once less than RECORDING_STOP_FREE_BYTES is left. The flush at the end
# waits at most FLUSH_TIMEOUT_S.
RECORDING_MIN_FREE_BYTES = 16 * 1024 * 1024
RECORDING_STOP_FREE_BYTES = 1024 * 1024
FLUSH_TIMEOUT_S = 120.0
# The scene's rows are sent in batches (`_Batch`) of this many scans, or, streamed to a live
# viewer, of what this many seconds brought (the viewer is behind the run by at most that; a
# file has no such limit: on a loaded machine it made batches of a few scans, and the cost of a
# send is mostly per call: some 0.5 ms of CPU a `send_columns` in rerun 0.41, whatever its
# rows, 15 a batch); 1: each row as it comes.
BATCH_SCANS = 1024
BATCH_S = 0.25
# The map's ellipses (`world/landmarks/ellipses`) are logged again when a landmark joined or left
# the map, else once this many seconds of the sequence's time have passed since they last were,
# and at the last scan: they shrink slowly, and at every scan of a long run they were most of a
# recording's bytes and time (a Victoria Park run: 550 MiB). The centres and ids: every scan.
ELLIPSES_EVERY_S = 1.0
# The map's ellipses are drawn with this many points (24 sides: the outline is within 0.9% of
# the ellipse, unseen at map scale; the PNG figures keep 41).
ELLIPSE_POINTS = 25
_NO_SCAN = object()
FLUSH_STEP_S = 1.0
_FULL_BYTES = 1024 * 1024  # a write error with less free than this: the disk is full
# Recordings whose file writer a write error stopped (rerun 0.41): disconnecting one, which
# rerun also does when it is garbage-collected and at exit, waits forever. They are kept here,
# and a command that made one ends at once (`writer_stopped`).
_STOPPED: list = []
log = logging.getLogger(__name__)


def writer_stopped() -> bool:
    """True when a recording of this process was stopped by a write error: its rerun stream
    cannot be shut down (it would wait forever), so the process must end with `os._exit`
    once its error is shown and its files are cleaned up (the CLI does)."""
    return bool(_STOPPED)


# The hues of the PNG figures (`experiments.render.plots.SEGMENT_COLORS`, `METHOD_COLORS`),
# lighter where the dark background needs it; no colour is used for two kinds of feature.
KIND_COLORS = np.array(  # segment class (`Features.segment_kind`): clutter, line, circle
    [[255, 150, 40], [60, 120, 255], [170, 105, 60]], dtype=np.uint8
)
METHOD_COLORS = {  # circles by fitting method
    "paper": [40, 200, 90],
    "geometric": [220, 60, 220],
    "bailey": [255, 200, 0],
    "kasa": [160, 110, 230],
    "taubin": [0, 200, 220],
    "truth": [255, 255, 255],
}
SCAN_POINT_PX = 2.0  # scan points: on-screen radius in UI points, readable at any zoom
FOLLOW_HALF_WIDTH_M = 15.0  # the following map view shows at least +-15 m around the vehicle
# names of series curves whose colour is fixed: bounds grey, the rest from the palette
_BOUND_COLOR = [150, 150, 150]
_CURVE_COLORS = [[255, 90, 90], [90, 170, 255], [120, 220, 120]]


def _transform(xy: np.ndarray, pose: np.ndarray | None) -> np.ndarray:
    if pose is None or len(xy) == 0:
        return xy
    return se2.transform_points(pose, xy)


def _parent(path: str) -> str:
    return path.rsplit("/", 1)[0]


def _y_up(frame: str) -> str:
    """A child of `frame` that mirrors y: rerun draws 2D views with y down (rerun issue 1387),
    so each view's origin is such a child, and the map reads as on paper, y up."""
    return f"{frame}/y_up"


# The rows logged at every scan, as columns (`columns.Spec`: each field a value a row, or
# `Const`, the same in every row); `_circles_spec` for circles by method.
_C = columns
_POSE = _C.Spec(rr.Transform3D, translation=_C.Vectors(3), rotation_axis_angle=_C.AxisZ())
_FOLLOW = _C.Spec(
    rr.Transform3D, translation=_C.Vectors(3), scale=_C.Const(rows.vectors([[1.0, -1.0, 1.0]]))
)


def _points(radius_ui: float, rgb: tuple[int, int, int]) -> columns.Spec:
    """Points2D: positions a row, one radius (UI points) and one colour."""
    return _C.Spec(
        rr.Points2D,
        positions=_C.Vectors(2),
        radii=_C.Const(rows.radii_ui(radius_ui)),
        colors=_C.Const(rows.color(*rgb)),
    )


def _lines(strips: columns.Kind, radius_ui: float, rgb: tuple[int, int, int]) -> columns.Spec:
    """LineStrips2D: strips a row (`strips`), one radius (UI points) and one colour."""
    return _C.Spec(
        rr.LineStrips2D,
        strips=strips,
        radii=_C.Const(rows.radii_ui(radius_ui)),
        colors=_C.Const(rows.color(*rgb)),
    )


_SCAN = _C.Spec(  # a row: the scan's ranges and angles (`columns.ScanPoints`)
    rr.Points2D,
    positions=_C.ScanPoints(),
    radii=_C.Const(rows.radii_ui(SCAN_POINT_PX)),
    colors=_C.Const(rows.color(200, 200, 200)),
)
_EDGES = _points(4.0, (255, 40, 40))
_TENTATIVES = _points(3.0, (255, 200, 0))
_SEGMENTS = _C.Spec(
    rr.LineStrips2D, strips=_C.Strips(), radii=_C.Const(rows.radii_ui(1.5)), colors=_C.Colors()
)
_LINES = _lines(_C.Pairs(), 2.0, (60, 120, 255))
_ASSOCIATIONS = _lines(_C.Pairs(), 1.0, (0, 200, 255))
_PATH = _lines(_C.Strips(), 1.5, (255, 80, 80))
_TRUE_PATH = _lines(_C.Strips(), 1.0, (255, 255, 255))
_VEHICLE_ELLIPSE = _lines(_C.Ellipses(40), 1.0, (255, 80, 80))  # (shapes.ellipse_polyline's)
_MAP_ELLIPSES = _lines(_C.Ellipses(ELLIPSE_POINTS - 1), 1.0, (40, 200, 90))
_VEHICLE_ARROW = _C.Spec(  # a row: the heading's sigma, rad
    rr.Arrows2D,
    vectors=_C.Const(rows.vectors([[2.0, 0.0]])),
    origins=_C.Const(rows.vectors([[0.0, 0.0]])),
    radii=_C.Const(rows.radii_ui(2.0)),
    colors=_C.Const(rows.color(255, 80, 80)),
    labels=_C.Formatted("heading +-{:.2f} deg (3 sigma)", lambda sig: np.degrees(3 * sig)),
)
_TRUE_ARROW = _C.Spec(
    rr.Arrows2D,
    vectors=_C.Vectors(2),
    origins=_C.Vectors(2),
    radii=_C.Const(rows.radii_ui(1.5)),
    colors=_C.Const(rows.color(255, 255, 255)),
)
_LANDMARKS = _C.Spec(
    rr.Points2D,
    positions=_C.Vectors(2),
    radii=_C.Const(rows.radii_ui(3.0)),
    colors=_C.Const(rows.color(40, 200, 90)),
    labels=_C.IdLabels("L"),
)
_LANDMARKS_EXISTENCE = _C.Spec(
    rr.Points2D,
    positions=_C.Vectors(2),
    radii=_C.Const(rows.radii_ui(3.0)),
    colors=_C.Colors(),
    labels=_C.Texts(),
)
_SCALARS = _C.Spec(rr.Scalars, scalars=_C.Floats())


@functools.cache
def _circles_spec(rgb: tuple[int, int, int], labelled: bool) -> columns.Spec:
    """Circles of one colour a row ([x, y, r], drawn at the flush), labelled with their
    radius (a row: the radii) or, for a row with no circle, not labelled."""
    labels = {"labels": _C.Formatted("r={:.2f} m")} if labelled else {}
    return _C.Spec(
        rr.LineStrips2D,
        strips=_C.Circles(),
        radii=_C.Const(rows.radii_ui(1.5)),
        colors=_C.Const(rows.color(*rgb)),
        **labels,
    )


# the frames that get a y_up child, by kind
_VIEW_FRAMES = {
    "slam": ("world", "world/laser"),
    "features": ("laser",),
    "circles": ("world", "figures"),
}


# Paths logged a piece a scan (the points since the last logged scan), drawn whole up to the time
# cursor by a visible time range on the entity (rerun's trails): the path so far at every scan
# without logging it all again at each one.
TRAILS = ("world/path", "world/truth/path")
_TRAIL = rrb.VisibleTimeRanges(
    [
        rrb.VisibleTimeRange(
            timeline,
            start=rrb.TimeRangeBoundary.infinite(),
            end=rrb.TimeRangeBoundary.cursor_relative(),
        )
        for timeline in ("scan", "time")
    ]
)


def _series_view(name: str, title: str) -> rrb.TimeSeriesView:
    return rrb.TimeSeriesView(origin=f"series/{name}", name=title)


def blueprint(
    kind: str, series: list[tuple[str, str]] = (), ellipse_scale: float = 1.0
) -> rrb.Blueprint:
    """The layout of a recording of `kind` (KINDS). series: (name, title) of the time series
    panels (slam and features)."""
    if kind not in KINDS:
        raise ValueError(f"kind: expected one of {KINDS}, got {kind!r}")
    panels = [_series_view(n, t) for n, t in series]
    collapsed = [rrb.BlueprintPanel(state="collapsed"), rrb.SelectionPanel(state="collapsed")]
    if kind == "features":
        scan = rrb.Spatial2DView(
            origin=_y_up("laser"),
            contents="/laser/**",
            name="scan and features, laser frame (x forward, m); segments: circle brown, "
            "line blue, clutter orange; circles: paper green, geometric magenta, Bailey yellow; "
            "edges red",
        )
        body = rrb.Vertical(scan, *panels, row_shares=[4] + [1] * len(panels))
        return rrb.Blueprint(body, rrb.TimePanel(timeline="time"), *collapsed)
    if kind == "circles":
        no_radius = {  # the pillars' names label them; radius labels would overlap
            f"world/circles/{m}": rr.LineStrips2D.from_fields(show_labels=False)
            for m in METHOD_COLORS
        }
        court = rrb.Spatial2DView(
            origin=_y_up("world"),
            contents="/world/**",
            overrides=no_radius,
            name="pillar court, world frame: one scan per position, circles by method, "
            "true pillars white",
        )
        figs = rrb.Spatial2DView(
            origin=_y_up("figures"),
            contents="/figures/**",
            name="figure scans (scan 100-105), all features",
        )
        return rrb.Blueprint(
            rrb.Horizontal(court, figs), rrb.TimePanel(timeline="scan"), *collapsed
        )
    map_overrides = {
        "world/laser/features/circles": rr.LineStrips2D.from_fields(show_labels=False),
        **{path: _TRAIL for path in TRAILS},
    }
    scale = f"ellipses 95%, drawn x{ellipse_scale:g}"
    h = FOLLOW_HALF_WIDTH_M
    follow = rrb.Spatial2DView(
        origin="world/follow",
        contents="/world/**",
        name=f"map following the vehicle (m; {scale})",
        visual_bounds=rrb.VisualBounds2D(x_range=[-h, h], y_range=[-h, h]),
        overrides=map_overrides,
    )
    whole = rrb.Spatial2DView(
        origin=_y_up("world"),
        contents="/world/**",
        name=f"whole map (m; {scale})",
        overrides=map_overrides,
    )
    scan = rrb.Spatial2DView(
        origin=_y_up("world/laser"),
        contents="/world/laser/**",
        name="scan and features, laser frame (x forward, m)",
        visual_bounds=rrb.VisualBounds2D(x_range=[-5.0, 35.0], y_range=[-20.0, 20.0]),
    )
    left = rrb.Vertical(rrb.Tabs(follow, whole), scan, row_shares=[3, 2])
    right = rrb.Grid(*panels, grid_columns=2) if panels else None
    body = rrb.Horizontal(left, right, column_shares=[3, 2]) if right else left
    return rrb.Blueprint(body, rrb.TimePanel(timeline="time"), *collapsed)


class _Track:
    """A path that grows a point at a time, logged a piece at a time (`piece`)."""

    def __init__(self) -> None:
        self._xy = np.empty((256, 2))
        self._n = 0
        self._mark = 0  # points already in a piece

    def append(self, xy) -> None:
        if self._n == len(self._xy):
            self._xy = np.concatenate([self._xy, np.empty_like(self._xy)])
        self._xy[self._n] = xy
        self._n += 1

    @property
    def xy(self) -> np.ndarray:
        return self._xy[: self._n]

    def piece(self) -> np.ndarray:
        """The points added since the last piece, after that piece's last point: the next
        piece of the path as a trail draws it (the first piece: the first point alone)."""
        start, end = self.span()
        return self._xy[start:end]

    def span(self) -> tuple[int, int]:
        """The next piece (`piece`) as [start, end) in `xy` (whose points never change)."""
        start, self._mark = max(self._mark - 1, 0), self._n
        return start, self._n

    def pieces(self, spans: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The pieces of `spans` (n, 2) [start, end) as a `columns.Strips` value of n rows of
        one strip each: (their points one after the other, their lengths)."""
        lengths = (spans[:, 1] - spans[:, 0]).astype(np.int32)
        first = np.repeat(spans[:, 0] - np.cumsum(lengths) + lengths, lengths)
        return self.xy[first + np.arange(len(first))], lengths


class _VehicleRows:
    """The vehicle's five entities of a batch (`world/vehicle`, `world/follow`,
    `world/vehicle/arrow`, `world/vehicle_ellipse`, `world/path`), kept as one record a scan:
    the pose and its covariance (12 numbers) and the path's piece in the track (`_Track.span`).
    At the flush (`into`) the records become the five entities' rows, every row of a field at
    once: the same values as a row a scan of each (`tests/experiments/test_recording_columns.py`)
    at a fifth of the calls."""

    def __init__(self, track: _Track, ellipse_scale: float) -> None:
        self.track = track
        self.scale2 = ellipse_scale**2
        self.values = columns._Grow((12,), np.float64)  # [x, y, theta, P (3, 3) row by row]
        self.spans = columns._Grow((2,), np.int64)
        self.scan: list[int] = []
        self.time: list[float] = []

    def add(self, k: int, stamp_s: float | None, pose: np.ndarray, cov: np.ndarray) -> None:
        g = self.values
        if g.n == len(g.a):
            g._room(1)
        g.a[g.n, :3] = pose
        g.a[g.n, 3:] = cov.reshape(-1)
        g.n += 1
        self.spans.put1(self.track.span())
        self.scan.append(k)
        self.time.append(np.nan if stamp_s is None else stamp_s)

    def into(self, batch: _Batch) -> None:
        """The records' rows into the batch's tables (nothing when there are none)."""
        if self.scan:
            scan, stamps, rows_of = self.take()
            for path, spec, values in rows_of:
                batch.table(path, spec).add_rows(scan, stamps, values)

    def take(self) -> tuple[list[int], list[float], list]:
        """(scans, times s, [(path, spec, values of every row of each field)]) of the
        records added since the last take."""
        v, spans = self.values.take(), self.spans.take()
        scan, self.scan = self.scan, []
        stamps, self.time = self.time, []
        xyz = np.zeros((len(v), 3))
        xyz[:, :2] = v[:, :2]
        ellipses = np.empty((len(v), 6))  # [x, y, the position's covariance, scaled]
        ellipses[:, :2] = v[:, :2]
        ellipses[:, 2:] = v[:, [3, 4, 6, 7]] * self.scale2
        rows_of = [
            ("world/vehicle", _POSE, (xyz, v[:, 2])),
            ("world/follow", _FOLLOW, (xyz,)),  # y mirrored: see _y_up
            ("world/vehicle/arrow", _VEHICLE_ARROW, (np.sqrt(np.maximum(v[:, 11], 0.0)),)),
            ("world/vehicle_ellipse", _VEHICLE_ELLIPSE, (ellipses,)),
            ("world/path", _PATH, (self.track.pieces(spans),)),
        ]
        return scan, stamps, rows_of


class _Batch:
    """The scene's rows of the last scans as columns (`columns.Table`, one an entity and
    `columns.Spec`), kept until BATCH_SCANS scans (or, with `max_s`, that many seconds) have
    passed and then sent with one `send_columns` an entity: rerun's cost of a logged row is
    mostly that of the call (a chunk each), and a Victoria Park run logs some 15 entities at
    each of 7,249 scans. At each scan a row only copies its values into the table's numpy
    buffers; the arrow arrays are built once a batch. With `one_by_one` the rows are logged
    each with `rec.log` at its own time instead (`batch_scans=1`: each scan's rows are sent at
    the next scan; `tests/experiments/test_live_viewer.py` compares the two row for row)."""

    def __init__(
        self,
        rec: rr.RecordingStream,
        scans: int,
        max_s: float | None = None,
        one_by_one: bool = False,
    ) -> None:
        self.rec = rec
        self.scans = scans
        self.max_s = max_s
        self.one_by_one = one_by_one
        self.tables: dict[tuple[str, columns.Spec], columns.Table] = {}
        self.records: list = []  # whose rows are made at the send (`into(batch)`)
        self._n = 0
        self._since = time.monotonic()

    def table(self, path: str, spec: columns.Spec) -> columns.Table:
        table = self.tables.get((path, spec))
        if table is None:
            table = self.tables[(path, spec)] = spec.table()
        return table

    def add(self, path: str, spec: columns.Spec, k: int, stamp_s: float | None, values) -> None:
        table = self.tables.get((path, spec))
        if table is None:
            table = self.tables[(path, spec)] = spec.table()
        table.add(k, stamp_s, values)

    def due(self) -> bool:
        """A scan is complete: True when the batch is full or old (then `send` it)."""
        self._n += 1
        old = self.max_s is not None and time.monotonic() - self._since > self.max_s
        return self._n >= self.scans or old

    def send(self) -> None:
        self._n, self._since = 0, time.monotonic()
        for record in self.records:  # (`_VehicleRows`: made into rows now)
            record.into(self)
        for (path, _), table in self.tables.items():
            if table.n:
                self._send(path, *table.take())

    def _send(self, path: str, scan: np.ndarray, stamp_s: np.ndarray, cols: list) -> None:
        timed = ~np.isnan(stamp_s)
        if self.one_by_one or timed.any() != timed.all():  # (rows with and without time)
            self._log_rows(path, scan, stamp_s, cols)
            return
        indexes = [rr.TimeColumn("scan", sequence=scan)]
        if timed.all():
            ns = np.rint(1e9 * stamp_s).astype(np.int64)  # as rerun's set_time: round(1e9 s)
            indexes.append(rr.TimeColumn("time", duration=ns.astype("timedelta64[ns]")))
        cols = [
            rr.ComponentColumn(d, rows.Described(d, array), offsets=offsets)
            for d, array, offsets in cols
        ]
        self.rec.send_columns(path, indexes=indexes, columns=cols)

    def _log_rows(self, path: str, scan: np.ndarray, stamp_s: np.ndarray, cols: list) -> None:
        """The rows logged one at a time (`rec.log`), each at its scan and time."""
        for i, k in enumerate(scan.tolist()):
            self.rec.set_time("scan", sequence=k)
            if not np.isnan(stamp_s[i]):
                self.rec.set_time("time", duration=float(stamp_s[i]))
            batches = [
                rows.Described(d, array.slice(o[i], o[i + 1] - o[i])) for d, array, o in cols
            ]
            self.rec.log(path, batches)


class Recorder(NullRecorder):
    """Writes a `.rrd` recording with its blueprint (open it with `rerun FILE.rrd`).

    The recording goes to a temporary file beside `path` (`.NAME.XXXX.rrd.tmp`) and is renamed
    to `path` by `close()`: an interrupted run never leaves a truncated recording at `path`.
    `abort()` (or leaving a `with` block by an exception) deletes the temporary file.

    A full disk: a recording is not started on a file system with less than
    `RECORDING_MIN_FREE_BYTES` free, and is stopped when its next batch is due (`_Batch`; the
    file grows only then) once less than `RECORDING_STOP_FREE_BYTES` is left; rerun's file
    writer (a thread of its own) stops at a write error, which shows when the recording is
    flushed. Each is a `WriteError` naming
    `path` and the reason (no space left, the process's file-size limit), with the temporary
    file deleted."""

    min_free_bytes = RECORDING_MIN_FREE_BYTES
    batch_s = None  # a batch is sent after BATCH_SCANS scans, however long they took

    def __init__(
        self,
        path: Path | str,
        kind: str = "slam",
        *,
        app_id: str | None = None,
        decimate: int = 1,
        ellipse_scale: float = 10.0,
        series: list[tuple[str, str]] = (),
        batch_scans: int = 0,
    ):
        """kind: "slam", "features" or "circles" (the blueprint). decimate: log the scene of
        every this-many scans only (paths and time series still get every scan); a whole
        Victoria Park run at 1 would be gigabytes. ellipse_scale: covariance ellipses are drawn
        this many times their 95% size (true size is invisible at map scale); the map views
        say so in their titles. series: (name, title) of the time series panels. batch_scans:
        the scene's rows are sent this many scans at a time (`_Batch`; 0: BATCH_SCANS, 1: each
        as it comes)."""
        self._settings(kind, decimate, ellipse_scale, batch_scans)
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        check_output_file(self.path, "recording")
        self._check_space(
            self.min_free_bytes,
            f"a recording is started with at least {self.min_free_bytes / 2**20:.0f} MiB free",
        )
        try:
            fd, tmp = tempfile.mkstemp(
                dir=self.path.parent, prefix=f".{self.path.name}.", suffix=".rrd.tmp"
            )
        except OSError as exc:
            raise WriteError(self.path, exc) from None
        os.close(fd)
        self._tmp = Path(tmp)
        try:
            self.rec = rr.RecordingStream(app_id or f"trunkslam_{kind}")
            self.rec.save(
                str(self._tmp), default_blueprint=blueprint(kind, list(series), self.ellipse_scale)
            )
            self._log_frames()
        except RuntimeError as exc:  # rerun's error when it cannot create the file
            self._tmp.unlink(missing_ok=True)
            raise DataError(f"recording {self.path}: cannot be written ({exc})") from None
        except BaseException:  # interrupted while opening: leave nothing behind
            self._tmp.unlink(missing_ok=True)
            raise

    def _settings(
        self, kind: str, decimate: int, ellipse_scale: float, batch_scans: int = 0
    ) -> None:
        """What every recording keeps, whatever its sink (see `__init__`)."""
        if kind not in KINDS:
            raise ValueError(f"kind: expected one of {KINDS}, got {kind!r}")
        if ellipse_scale <= 0:
            raise ValueError(f"ellipse_scale: must be > 0, got {ellipse_scale!r}")
        self.kind = kind
        self.decimate = max(int(decimate), 1)
        self.ellipse_scale = float(ellipse_scale)
        self._k = 0
        self._posed = None  # (scan, frame, pose) last logged by _log_pose
        self._stamp = _NO_SCAN  # the current scan's time, s (None: none); _NO_SCAN: no scan yet
        self._batch = None
        self._batch_scans = BATCH_SCANS if batch_scans == 0 else int(batch_scans)
        self._timed = False  # rerun's own time is this scan's (`_at_scan`)
        self._est_path = _Track()
        self._truth_path = _Track()
        self._map = None  # the map's (ids, centres, covariances) at its last scan
        self._map_logged = (None, None)  # (ids, time s) of the ellipses last logged
        self._empty: set[str] = set()  # the paths whose last row held no item (`_put_items`)

    def _log_frames(self) -> None:
        """The static y mirrors under the views' frames (`_y_up`); the batch starts."""
        for frame in _VIEW_FRAMES[self.kind]:
            self.rec.log(_y_up(frame), rr.Transform3D(scale=[1.0, -1.0, 1.0]), static=True)
        one_by_one = self._batch_scans == 1
        self._batch = _Batch(self.rec, self._batch_scans, self.batch_s, one_by_one)
        self._vehicle = _VehicleRows(self._est_path, self.ellipse_scale)
        self._batch.records.append(self._vehicle)

    def _send_batch(self) -> None:
        """The map's ellipses at the last scan, when not yet logged; then the batch goes."""
        if self._map is not None:
            self._log_ellipses(*self._map)
            self._map = None
        if self._batch is not None:
            self._batch.send()

    def _check_space(self, least: int, rule: str) -> None:
        """`WriteError` (no space left) when the recording's file system has less than `least`
        bytes free."""
        if least <= 0:
            return
        try:
            free = shutil.disk_usage(self.path.parent).free
        except OSError:
            return
        if free < least:
            reason = f"No space left on device (only {free / 2**20:.1f} MiB free; {rule})"
            raise WriteError(self.path, OSError(errno.ENOSPC, reason))

    def _failed(self) -> OSError | None:
        """Why rerun's file writer has stopped, when it surely has (it does not say, and a
        flush then waits for it in vain): the disk is full, or the file reached this process's
        file-size limit. None otherwise."""
        try:
            if shutil.disk_usage(self.path.parent).free < _FULL_BYTES:
                return OSError(errno.ENOSPC, "No space left on device")
            limit = resource.getrlimit(resource.RLIMIT_FSIZE)[0]
            if limit != resource.RLIM_INFINITY and self._tmp.stat().st_size >= limit:
                return OSError(
                    errno.EFBIG, f"File too large (this process's file-size limit, {limit} bytes)"
                )
        except (OSError, AttributeError):
            pass
        return None

    def _why(self, exc: Exception) -> OSError:
        """Why the flush failed: `_failed`'s reason, or rerun's words."""
        return self._failed() or OSError(errno.EIO, f"the recording could not be written ({exc})")

    def _flush(self) -> None:
        """Flush the recording, a second at a time: rerun's file writer, stopped by a write
        error meanwhile, never answers a flush, so between the waits `_failed` looks for the
        reason (a `WriteError`). RuntimeError when rerun reports an error, or after
        FLUSH_TIMEOUT_S without one."""
        deadline = time.monotonic() + FLUSH_TIMEOUT_S
        while True:
            start = time.monotonic()
            try:
                self.rec.flush(timeout_sec=FLUSH_STEP_S)
                return
            except RuntimeError:
                why = self._failed()
                if why is not None:
                    raise WriteError(self.path, why) from None
                now = time.monotonic()
                if now - start < FLUSH_STEP_S / 2 or now > deadline:  # an error, not a wait
                    raise

    def _skip(self) -> bool:
        return self._k % self.decimate != 0

    def set_scan(self, k: int, stamp_s: float | None = None) -> None:
        """Timeline `scan` = k; with the scan's time, also timeline `time` (seconds). The rows
        of the scans before go when their batch is due, after a look at the free space (the
        file grows only when a batch goes: a disk filling up stops the run there, not at its
        end)."""
        self._k = int(k)
        interruption_point("recording-scan")  # the interruption tests' Ctrl-C, mid-recording
        if self._stamp is not _NO_SCAN and self._batch.due():
            self._check_writer()
            self._batch.send()
        self._stamp = None if stamp_s is None else float(stamp_s)
        self._timed = False

    def _check_writer(self) -> None:
        """Stop the recording (`WriteError`, nothing left) when its disk is nearly full or its
        file writer has stopped."""
        if self._tmp is None:
            return
        try:
            self._check_space(RECORDING_STOP_FREE_BYTES, "the recording was stopped")
            why = self._failed()
            if why is not None:
                raise WriteError(self.path, why)
        except WriteError:
            self.abort()
            raise

    def _at_scan(self) -> None:
        """rerun's own time set to this scan, for a row logged at once (`rec.log`)."""
        if self._timed or self._stamp is _NO_SCAN:
            return
        self._timed = True
        self.rec.set_time("scan", sequence=self._k)
        if self._stamp is not None:
            self.rec.set_time("time", duration=self._stamp)

    def _put(self, path: str, spec: columns.Spec, *values) -> None:
        """A row of `spec` at `path` at this scan, the values of its `columns.Kind` fields in
        order, into the batch (before any scan: logged at once, without a time)."""
        if self._stamp is not _NO_SCAN:
            self._batch.add(path, spec, self._k, self._stamp, values)
            return
        table = spec.table()
        table.add(0, None, values)
        self._log_now(path, table)

    def _put_items(self, path: str, spec: columns.Spec, n: int, *values) -> None:
        """`_put` of a row of `n` items (points, strips, circles), except a row of none after
        a row of none at `path`: rerun shows at each time the latest row at or before it, so
        the viewer shows nothing there either way, and the row costs a call and a copy (a
        Victoria Park run's features have no segment, line or edge at any of its 7,249 scans,
        and no circle, tentative or association at many)."""
        if n == 0:
            if path in self._empty:
                return
            self._empty.add(path)
        else:
            self._empty.discard(path)
        self._put(path, spec, *values)

    def _log_now(self, path: str, table: columns.Table) -> None:
        """The table's one row logged at once, at rerun's current time (`rec.log`)."""
        _, _, cols = table.take()
        self.rec.log(path, [rows.Described(d, array) for d, array, _ in cols])

    def _log_pose(self, frame: str, pose) -> None:
        """The frame entity's pose at this scan, once (a scan and its features share it)."""
        if pose is None:
            return
        key = (self._k, frame, *np.asarray(pose, float).tolist())
        if key != self._posed:
            self._posed = key
            self._put(frame, _POSE, [[key[2], key[3], 0.0]], key[4:])

    def log_scan(self, scan: Scan, pose=None, path: str = "world/laser/scan") -> None:
        """Scan points in the laser frame at `path`. With `pose` (the laser's world pose), the
        parent of `path` is the laser's frame entity and gets the pose."""
        if self._skip():
            return
        self._log_pose(_parent(path), pose)
        self._put(path, _SCAN, (scan.ranges_m, scan.angle_min_rad, scan.angle_increment_rad))

    def log_features(
        self, scan: Scan | None, features: Features, pose=None, path="world/laser/features"
    ):
        """Segments, circles, lines and edges in the laser frame under `path`; with `pose`, as
        `log_scan` (the parent of `path` gets the laser's world pose). scan: the scan the
        segments index (None: features without segments, e.g. a sequence of detections)."""
        if self._skip():
            return
        self._log_pose(_parent(path), pose)
        beams = features.segment_beams
        if len(beams) and scan is None:
            raise ValueError("log_features: segments need the scan their beams index, got None")
        strips = [scan.points_xy[features.beams(a, b)] for a, b in beams] if len(beams) else []
        kinds = np.asarray(features.segment_kind, np.int64).reshape(-1)
        segments = (columns.strips(strips), KIND_COLORS[kinds])
        self._put_items(f"{path}/segments", _SEGMENTS, len(strips), *segments)
        self.log_circles(f"{path}/circles", features.circle_params, None, features.method)
        ends = np.asarray(features.line_endpoints).reshape(-1, 4)
        self._put_items(f"{path}/lines", _LINES, len(ends), ends)
        edges = np.asarray(features.edge_xy, float).reshape(-1, 2)
        self._put_items(f"{path}/edges", _EDGES, len(edges), edges)

    def log_circles(
        self, path, circles_xyr, pose=None, method="truth", labels=None, static=False
    ) -> None:
        """Circles (C, 3) [x, y, r] as outlines labelled with their radius (or `labels`; [] for
        none); `pose` transforms them into the world; static: for all times (truth)."""
        circles_xyr = np.asarray(circles_xyr, float).reshape(-1, 3)
        rgb = tuple(METHOD_COLORS.get(method, [255, 255, 255]))
        if pose is None and labels is None and not static:  # drawn and labelled at the flush
            if len(circles_xyr):
                self._put_items(
                    path, _circles_spec(rgb, True), len(circles_xyr), circles_xyr, circles_xyr[:, 2]
                )
            else:
                self._put_items(path, _circles_spec(rgb, False), 0, circles_xyr)
            return
        strips = circle_polylines(circles_xyr)
        if pose is not None and len(strips):
            strips = _transform(strips.reshape(-1, 2), pose).reshape(strips.shape)
        if labels is None:
            labels = [f"r={c[2]:.2f} m" for c in circles_xyr]
        fields = {
            "strips": rows.strips(strips),
            "radii": rows.radii_ui(1.5),
            "colors": rows.color(*rgb),
        }
        if len(labels):
            fields["labels"] = rows.labels(labels)
        self._log(path, rows.row(rr.LineStrips2D, **fields), static=static)

    def _log(self, path: str, row: rows.Row, static: bool = False) -> None:
        """Log `row` at `path` now: at this scan, or for all times (static)."""
        if not static:
            self._at_scan()
        self.rec.log(path, row, static=static)

    # ---- SLAM (the visualiser interface of slam.run_slam; world frame) -----------------------

    def log_truth_trees(self, circles_xyr) -> None:
        """Simulated trees (L, 3) [x, y, r], world frame, for all times: white dots (seen at any
        zoom) under their true outlines."""
        circles_xyr = np.asarray(circles_xyr, float).reshape(-1, 3)
        self.rec.log(
            "world/truth/trees",
            rr.Points2D(
                circles_xyr[:, :2], radii=rr.Radius.ui_points(4.5), colors=[[255, 255, 255]]
            ),
            static=True,
        )
        self.log_circles("world/truth/trees/outline", circles_xyr, labels=[], static=True)

    def log_vehicle(self, pose, cov) -> None:
        """Estimated pose (frame entity and arrow), 95% position ellipse and the path so far."""
        pose = np.asarray(pose, float)
        self._est_path.append(pose[:2])
        if self._skip():
            return
        if self._stamp is not _NO_SCAN:
            self._vehicle.add(self._k, self._stamp, pose, np.asarray(cov, float))
            return
        self._vehicle.add(0, None, pose, np.asarray(cov, float))  # before any scan: at once
        _, _, rows_of = self._vehicle.take()
        for path, spec, values in rows_of:
            table = spec.table()
            table.add_rows([0], [np.nan], values)
            self._log_now(path, table)

    def log_landmarks(self, xy, cov, ids, existence=None) -> None:
        """The map; existence (n,): map policy "existence", each landmark's, in its label and
        its colour (green at 1, through yellow, to red at 0)."""
        if self._skip():
            return
        xy = np.asarray(xy, float).reshape(-1, 2)
        ids = np.array(ids, np.int64).reshape(-1)
        if existence is None:  # one colour, the ids' labels
            self._put("world/landmarks", _LANDMARKS, xy, ids)
        else:
            r = np.clip(np.nan_to_num(np.asarray(existence, float), nan=0.0), 0.0, 1.0)
            labels = [f"L{int(i)} r={v:.3f}" for i, v in zip(ids, r)]
            colors = np.column_stack(
                [255 * np.minimum(1.0, 2 * (1 - r)), 200 * np.minimum(1.0, 2 * r), 60 + 0 * r]
            ).astype(np.uint8)
            self._put("world/landmarks", _LANDMARKS_EXISTENCE, xy, colors, labels)
        last_ids, last_s = self._map_logged
        self._map = (ids, xy.copy(), np.array(cov, dtype=float))  # scaled when logged
        if (
            not isinstance(self._stamp, float)
            or last_s is None
            or not np.array_equal(ids, last_ids)
            or self._stamp - last_s >= ELLIPSES_EVERY_S
        ):
            self._log_ellipses(*self._map)
            self._map = None

    def _log_ellipses(self, ids, xy, cov) -> None:
        """The map's ellipses (covariances `cov`, drawn `ellipse_scale` times their size) at
        this scan (see ELLIPSES_EVERY_S)."""
        self._map_logged = (ids, self._stamp)
        scaled = np.asarray(cov, float).reshape(-1, 4) * self.ellipse_scale**2
        self._put("world/landmarks/ellipses", _MAP_ELLIPSES, np.hstack([xy, scaled]))

    def log_tentatives(self, xy) -> None:
        if self._skip():
            return
        xy = np.asarray(xy, float).reshape(-1, 2)
        self._put_items("world/tentative", _TENTATIVES, len(xy), xy)

    def log_associations(self, from_xy, to_xy) -> None:
        if self._skip():
            return
        a = np.asarray(from_xy, float).reshape(-1, 2)
        b = np.asarray(to_xy, float).reshape(-1, 2)
        self._put_items("world/associations", _ASSOCIATIONS, len(a), np.concatenate((a, b), axis=1))

    def log_closure(self, event: dict) -> None:
        """A loop-closure match (`slam.closure.ClosureEvent.to_dict()`) as a line of the text
        log `events/closures` at this scan, whatever the decimation: accepted ones at level
        INFO with the landmarks merged, refused ones at DEBUG with the reason."""
        e = event
        text = (
            f"loop closure {e['outcome']}: {e['best']} landmarks (next best {e['second']}), "
            f"shift {e['shift_m']:.2f} m, rotation {e['rotation_deg']:.2f} deg"
        )
        if e["nis"] == e["nis"]:
            text += f", joint NIS {e['nis']:.1f} (bound {e['nis_bound']:.1f})"
        for key, name in (("drift", "dead-reckoning"), ("shape", "rigid-fit")):
            v = e.get(f"{key}_nis", float("nan"))
            if v == v:
                text += f", {name} NIS {v:.1f} (bound {e[f'{key}_bound']:.1f})"
        if e.get("re_registered"):
            text += "; local map re-registered"
        if e["merged"]:
            text += f"; {len(e['merged'])} landmarks merged"
        level = rr.TextLogLevel.INFO if e["outcome"] == "accepted" else rr.TextLogLevel.DEBUG
        self._at_scan()
        self.rec.log("events/closures", rr.TextLog(text, level=level))

    def log_departures(self, departures: list) -> None:
        """The landmarks that left the map at this scan, (id, reason, existence) each (map
        policy "existence", `slam.log.SlamLog.departures`), as lines of the text log
        `events/map`, whatever the decimation."""
        self._at_scan()
        for lid, why, r in departures:
            text = f"L{int(lid)} left the map: {why} (existence {float(r):.4f})"
            self.rec.log("events/map", rr.TextLog(text, level=rr.TextLogLevel.INFO))

    def log_duplicates(self, pairs: list) -> None:
        """The duplicate sweep's merges at this scan (`slam.closure`, step 5: (kept id,
        dropped id) each) as a line of the text log `events/closures`, whatever the
        decimation."""
        merged = ", ".join(f"{b} into {a}" for a, b in pairs)
        text = f"duplicate sweep: {len(pairs)} landmarks marginalised out ({merged})"
        self._at_scan()
        self.rec.log("events/closures", rr.TextLog(text, level=rr.TextLogLevel.INFO))

    def log_truth(self, pose) -> None:
        """True pose (arrow) and path so far."""
        pose = np.asarray(pose, float)
        self._truth_path.append(pose[:2])
        if self._skip():
            return
        arrow = [[2 * np.cos(pose[2]), 2 * np.sin(pose[2])]]
        self._put("world/truth/vehicle", _TRUE_ARROW, arrow, [pose[:2]])
        piece = self._truth_path.piece()
        self._put("world/truth/path", _TRUE_PATH, (piece, np.array([len(piece)], np.int32)))

    # ---- time series -----------------------------------------------------------------------------

    def log_scalars(self, name: str, values: dict[str, float]) -> None:
        """One row of the series `series/<name>` at the current scan, one curve per key."""
        self._put(f"series/{name}", _SCALARS, np.fromiter(values.values(), float, len(values)))
        if name not in self.__dict__.setdefault("_styled", set()):
            self._styled.add(name)
            self._style(name, tuple(values), points=False)

    def _style(self, name: str, curves: tuple[str, ...], points: bool) -> None:
        colors = [
            _BOUND_COLOR
            if "sigma" in c or "%" in c
            else METHOD_COLORS.get(c, _CURVE_COLORS[i % len(_CURVE_COLORS)])
            for i, c in enumerate(curves)
        ]
        if points:
            style = rr.SeriesPoints(names=list(curves), colors=colors, marker_sizes=[1.5])
        else:
            style = rr.SeriesLines(names=list(curves), colors=colors)
        self.rec.log(f"series/{name}", style, static=True)

    def log_series(self, scan_t, series) -> None:
        """Whole series at once (`experiments.eval.series.Series`), on both timelines; scan_t
        (N,): the run's scan times, s."""
        scan_t = np.asarray(scan_t, float)
        for s in series:
            k = np.asarray(s.scan, np.int64)
            self.rec.send_columns(
                f"series/{s.name}",
                indexes=_scan_columns(k, scan_t),
                columns=rr.Scalars.columns(scalars=np.asarray(s.values, float)),
            )
            if not s.points:
                self._break_at_gaps(s.name, k, scan_t)
            self._style(s.name, s.curves, s.points)

    def _break_at_gaps(self, name: str, k: np.ndarray, scan_t: np.ndarray) -> None:
        """rerun joins consecutive values of a line series, across scans with none (NIS at scans
        without an update): a clear at the first scan of each such gap stops the lines there."""
        gap = k[np.flatnonzero(np.diff(k) > 1)] + 1
        if gap.size == 0:
            return
        self.rec.send_columns(
            f"series/{name}",
            indexes=_scan_columns(gap, scan_t),
            columns=rr.Clear.columns(is_recursive=np.zeros(gap.size, bool)),
        )

    def close(self) -> None:
        """Finish the file (its footer, which readers use to list its stores), flush it to
        disk and put it at `path` (atomically: a rename). A write error: `WriteError` naming
        `path`, nothing left."""
        if self._tmp is None:
            return
        why = self._failed()
        if why is not None:  # no flush: it would wait FLUSH_TIMEOUT_S for a stopped writer
            self.abort()
            raise WriteError(self.path, why)
        try:
            self._send_batch()
            self._flush()
            self.rec.disconnect()  # closes the file sink
            fd = os.open(self._tmp, os.O_RDONLY)
            try:
                os.fsync(fd)
            finally:
                os.close(fd)
            os.chmod(self._tmp, 0o644)
            os.replace(self._tmp, self.path)
        except WriteError:
            self.abort()
            raise
        except RuntimeError as exc:  # rerun's file writer stopped, or the flush timed out
            why = self._why(exc)
            self.abort()
            raise WriteError(self.path, why) from None
        except OSError as exc:
            self.abort()
            raise WriteError(self.path, exc) from None
        except BaseException:
            self.abort()
            raise
        self._tmp = None

    def abort(self) -> None:
        """Drop the recording: the temporary file is deleted, `path` is left as it was."""
        if self._tmp is None:
            return
        if self._failed() is None:
            with contextlib.suppress(Exception):
                self.rec.disconnect()
        else:  # a stopped file writer never answers a disconnect, nor rerun's own at exit
            _STOPPED.append(self.rec)
        self._tmp.unlink(missing_ok=True)
        self._tmp = None


class MemoryRecorder(Recorder):
    """A `Recorder` whose recording ends as bytes (`data`, once closed) instead of a file at a
    chosen path: a recording made where it is not written (a trial on a worker process, perhaps
    on another machine; the main process writes the bytes). It records into a private temporary
    folder, removed when the recorder is closed or aborted; the bytes are those of the file a
    `Recorder` would have written. (No free-space minimum: the bytes are written, and checked,
    where they are kept.)"""

    min_free_bytes = 0

    def __init__(self, kind: str = "slam", **kwargs) -> None:
        self._dir = Path(tempfile.mkdtemp(prefix="trunkslam-rrd-"))
        self.data: bytes | None = None
        try:
            super().__init__(self._dir / f"{kind}.rrd", kind, **kwargs)
        except BaseException:
            shutil.rmtree(self._dir, ignore_errors=True)
            raise

    def close(self) -> None:
        try:
            super().close()
            if self.data is None:
                self.data = self.path.read_bytes()
        finally:
            shutil.rmtree(self._dir, ignore_errors=True)

    def abort(self) -> None:
        super().abort()
        shutil.rmtree(self._dir, ignore_errors=True)


def _spawn(rec: rr.RecordingStream, viewer: Viewer, layout: rrb.Blueprint) -> None:
    """Start a rerun viewer on `viewer.port` (or use one listening there) and stream `rec` to
    it (`rr.spawn`); the one place a window may open (tests replace it)."""
    rr.spawn(
        port=viewer.port, executable_path=viewer_program(), default_blueprint=layout, recording=rec
    )


class LiveRecorder(Recorder):
    """A `Recorder` that streams to a live viewer (`experiments.render.rerun_sink.Viewer`:
    `--rerun spawn` or `connect[=ADDR]`) instead of writing a file: the same entities, the same
    layout (the blueprint goes to the viewer as the recording's default). Nothing is written
    on this machine, so there is no staging and no free-space check. The viewer's address was
    checked before the run (`rerun_sink.rerun_target`); one that stops answering during the
    run loses the rest of the stream, and `close` says so as a warning, not an error: the run's
    own files are still written."""

    batch_s = BATCH_S  # a batch is sent at least this often: the viewer lags by at most that

    def __init__(
        self,
        viewer: Viewer,
        kind: str = "slam",
        *,
        app_id: str | None = None,
        decimate: int = 1,
        ellipse_scale: float = 10.0,
        series: list[tuple[str, str]] = (),
        batch_scans: int = 0,
    ):
        self._settings(kind, decimate, ellipse_scale, batch_scans)
        self.viewer = viewer
        self.path = None
        self._tmp = None
        self._live = False
        self.rec = rr.RecordingStream(app_id or f"trunkslam_{kind}")
        layout = blueprint(kind, list(series), self.ellipse_scale)
        try:
            if viewer.mode == "spawn":
                _spawn(self.rec, viewer, layout)
            else:
                self.rec.connect_grpc(viewer.url, default_blueprint=layout)
        except RuntimeError as exc:  # rerun's error: no viewer program, a bad address
            raise ConfigError(f"{viewer}: the viewer cannot be reached ({exc})") from None
        self._live = True
        self._log_frames()

    def close(self) -> None:
        """Send what is left and close the stream (waits at most FLUSH_TIMEOUT_S)."""
        if not self._live:
            return
        self._live = False
        try:
            self._send_batch()
            self.rec.flush(timeout_sec=FLUSH_TIMEOUT_S)
        except RuntimeError as exc:
            log.warning(
                "%s: the viewer at %s stopped answering (%s)", self.viewer, self.viewer.url, exc
            )
        with contextlib.suppress(Exception):
            self.rec.disconnect()

    def abort(self) -> None:
        """Close the stream without waiting for what is not yet sent."""
        if not self._live:
            return
        self._live = False
        with contextlib.suppress(Exception):
            self.rec.disconnect()


def open_recording(
    target: Path | str | Viewer | None,
    kind: str = "slam",
    *,
    decimate: int = 1,
    ellipse_scale: float = 10.0,
    series: list[tuple[str, str]] = (),
) -> NullRecorder:
    """A Recorder writing to the file `target` (see `Recorder`), a LiveRecorder streaming to
    the viewer `target` (`rerun_sink.Viewer`), or a NullRecorder when target is None."""
    if target is None:
        return NullRecorder()
    settings = {"decimate": decimate, "ellipse_scale": ellipse_scale, "series": list(series)}
    if isinstance(target, Viewer):
        return LiveRecorder(target, kind, **settings)
    return Recorder(target, kind, **settings)


def _scan_columns(k: np.ndarray, scan_t: np.ndarray) -> list:
    """The timelines of scans k: `scan` (index) and `time` (the scan's time, s)."""
    return [rr.TimeColumn("scan", sequence=k), rr.TimeColumn("time", duration=scan_t[k])]
