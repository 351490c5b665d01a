"""A recording's rows kept as columns until they are sent (`viz.Recorder`).

At each scan a recording logs some 15 entities; making each a row of arrow arrays (or of rerun
archetypes) costs a few Python objects and calls per component, which over a 7,249-scan
Victoria Park run was most of what a recording cost. Here each entity is a `Table`: at each
scan `add` only copies the scan's values into preallocated numpy buffers, one per component
(the values, and how many of them the row holds), plus the row's scan and time; at a batch's
flush `take` builds each component's arrow array once for all the batch's rows (rerun's
arrow types, from `rows`' builders, which `tests/experiments/test_recording_rows.py` checks
against rerun's own conversion) with the rows' offsets, ready for `rr.send_columns`.

What the shapes of a row's values are is said by its `Spec`: one `Kind` a component, in the
archetype's field order. Some values are kept raw and drawn at the flush, for all the batch's
rows in one vectorised call: covariance ellipses (centre and covariance), circles (centre and
radius), labels made from numbers (their text). A component whose value is the same in every
row (a colour, a radius) is a `Const`: it takes no value and is repeated at the flush.
This module does not import rerun (`viz` does, and passes its archetype classes).
"""

from __future__ import annotations

import itertools
from collections.abc import Callable

import numpy as np
import pyarrow as pa

from experiments.render import rows
from experiments.render.shapes import circle_polylines, ellipse_polylines

__all__ = [
    "AxisZ",
    "Circles",
    "Colors",
    "Const",
    "Ellipses",
    "Floats",
    "Formatted",
    "IdLabels",
    "Pairs",
    "ScanPoints",
    "Spec",
    "Strips",
    "Table",
    "Texts",
    "Vectors",
]


class _Grow:
    """A numpy array filled along its first axis, preallocated and doubled when full. `take`
    hands the filled part over (the next values go to a new array: arrow may keep a view of
    the one it was given)."""

    __slots__ = ("a", "n")

    def __init__(self, tail: tuple = (), dtype=np.float32, capacity: int = 64) -> None:
        self.a = np.empty((capacity, *tail), dtype)
        self.n = 0

    def _room(self, m: int) -> None:
        need = self.n + m
        if need > len(self.a):
            bigger = np.empty((max(need, 2 * len(self.a)), *self.a.shape[1:]), self.a.dtype)
            bigger[: self.n] = self.a[: self.n]
            self.a = bigger

    def put(self, values) -> int:
        """Append (m, *tail) values; returns m."""
        m = len(values)
        if self.n + m > len(self.a):
            self._room(m)
        self.a[self.n : self.n + m] = values
        self.n += m
        return m

    def put1(self, value) -> None:
        """Append one value."""
        if self.n == len(self.a):
            self._room(1)
        self.a[self.n] = value
        self.n += 1

    def take(self) -> np.ndarray:
        out = self.a[: self.n]
        self.a = np.empty_like(self.a)
        self.n = 0
        return out


def _offsets(lengths) -> np.ndarray:
    """int32 offsets (n + 1,) of n rows of `lengths` (an array or a list)."""
    out = np.zeros(len(lengths) + 1, np.int32)
    np.cumsum(lengths, out=out[1:])
    return out


class Kind:
    """How a component's values of a row are kept: `column()` makes the buffers of one table's
    column, whose `put(value)` appends a row's value (an array, first axis: the instances) and
    whose `take()` returns (arrow array of every row's instances, int32 offsets of the rows)."""

    def column(self) -> _Column:
        raise NotImplementedError


class _Column:
    """A column's values in one buffer (`tail`, `dtype`), made arrow by `to_arrow`; how many
    each row holds in a list (an append costs less than a numpy store)."""

    __slots__ = ("lengths", "to_arrow", "values")

    def __init__(self, tail: tuple, dtype, to_arrow: Callable) -> None:
        self.values = _Grow(tail, dtype)
        self.lengths: list[int] = []
        self.to_arrow = to_arrow

    def put(self, value) -> None:
        g = self.values  # (`_Grow.put`, inline: a recording makes some 100,000 of these)
        m = len(value)
        if g.n + m > len(g.a):
            g._room(m)
        g.a[g.n : g.n + m] = value
        g.n += m
        self.lengths.append(m)

    def put_rows(self, values) -> None:
        """The values of len(values) rows of one instance each."""
        self.lengths.extend([1] * self.values.put(values))

    def take(self) -> tuple[pa.Array, np.ndarray]:
        lengths, self.lengths = self.lengths, []
        return self.to_arrow(self.values.take()), _offsets(lengths)


class Vectors(Kind):
    """(m, d) floats: rerun's Vec2D/Vec3D components (positions, translations), as float32."""

    def __init__(self, d: int) -> None:
        self.d = d

    def column(self) -> _Column:
        return _Column((self.d,), np.float32, rows._VECTORS.arrow)


class AxisZ(Kind):
    """(m,) angles, rad: rotations about z (rerun's RotationAxisAngle), as float32."""

    def column(self) -> _Column:
        return _Column((), np.float32, rows._AXIS_Z.arrow)


class Colors(Kind):
    """(m, 3) uint8 RGB: rerun's Color components (`rows.colors`), packed at the flush."""

    def column(self) -> _Column:
        return _Column((3,), np.uint8, lambda rgb: rows._U32S.arrow(rows.colors(rgb).data))


class Floats(Kind):
    """(m,) float64 (rerun's Scalar components)."""

    def column(self) -> _Column:
        return _Column((), np.float64, pa.array)


class IdLabels(Kind):
    """(m,) integer ids labelled `prefix` + id ("L12"); the texts are taken at the flush from
    a table of every id's label up to the largest seen (made once, grown as ids grow; the
    texts of `rows.id_labels`)."""

    def __init__(self, prefix: str) -> None:
        self.prefix = prefix
        self._labels = pa.array([], pa.string())

    def _arrow(self, ids: np.ndarray) -> pa.Array:
        if len(ids) == 0 or ids.min() < 0 or ids.max() >= 1 << 20:  # (no table for those)
            return rows._id_labels(self.prefix).arrow(ids)
        top = int(ids.max())
        if top >= len(self._labels):
            every = np.arange(max(top + 1, 2 * len(self._labels)), dtype=np.int64)
            self._labels = rows._id_labels(self.prefix).arrow(every)
        return self._labels.take(pa.array(ids))

    def column(self) -> _Column:
        return _Column((), np.int64, self._arrow)


class ScanPoints(Kind):
    """A scan's points in its own frame, the returns only: a row's value is (ranges (B,) m,
    NaN for no return, angle_min rad, angle_increment rad), and the points are made at the
    flush as `features.Scan` makes them (`points_xy[valid]`: the same products of each range
    with the cosine and sine of its beam's angle, the angles computed as `Scan.angles_rad`
    does, once for each laser geometry)."""

    def __init__(self) -> None:
        self._trig: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}

    def trig(self, n: int, angle_min: float, increment: float) -> tuple[np.ndarray, np.ndarray]:
        key = (n, angle_min, increment)
        if key not in self._trig:
            a = angle_min + increment * np.arange(n)  # (Scan.angles_rad)
            self._trig[key] = (np.cos(a), np.sin(a))
        return self._trig[key]

    def column(self) -> _ScanColumn:
        return _ScanColumn(self)


class _ScanColumn:
    __slots__ = ("beams", "geometry", "kind", "ranges")

    def __init__(self, kind: ScanPoints) -> None:
        self.kind = kind
        self.ranges = _Grow((), np.float64)
        self.geometry = _Grow((3,), np.float64)  # [B, angle_min, angle_increment] a row

    def put(self, value) -> None:
        ranges, angle_min, increment = value
        self.geometry.put1((self.ranges.put(ranges), angle_min, increment))

    def take(self) -> tuple[pa.Array, np.ndarray]:
        ranges, geometry = self.ranges.take(), self.geometry.take()
        starts = np.cumsum(geometry[:, 0].astype(np.int64)) - geometry[:, 0].astype(np.int64)
        points, lengths = [], np.empty(len(geometry), np.int32)
        # the rows in runs of one laser geometry, each run at once: (rows, beams) ranges
        change = np.flatnonzero((geometry[1:] != geometry[:-1]).any(axis=1)) + 1
        bounds = [0, *change.tolist(), len(geometry)] if len(geometry) else []  # no rows: none
        for i, j in itertools.pairwise(bounds):
            n, a0, da = geometry[i].tolist()
            r = ranges[starts[i] : starts[i] + (j - i) * int(n)].reshape(j - i, int(n))
            cos, sin = self.kind.trig(int(n), a0, da)
            valid = np.isfinite(r)
            points.append(np.stack([r * cos, r * sin], axis=2)[valid])
            lengths[i:j] = valid.sum(axis=1)
        flat = np.concatenate(points) if points else np.zeros((0, 2))
        return rows._VECTORS.arrow(flat.astype(np.float32)), _offsets(lengths)


class Formatted(Kind):
    """(m,) numbers labelled `fmt.format(f(v))` (`f`: a vectorised function of the numbers,
    or none); the texts are made at the flush."""

    def __init__(self, fmt: str, f: Callable | None = None) -> None:
        self.fmt = fmt
        self.f = f

    def _arrow(self, values: np.ndarray) -> pa.Array:
        if self.f is not None:
            values = self.f(values)
        fmt = self.fmt.format
        return pa.array([fmt(v) for v in values.tolist()], pa.string())

    def column(self) -> _Column:
        return _Column((), np.float64, self._arrow)


class Ellipses(Kind):
    """(m, 6) [cx, cy, c00, c01, c10, c11]: m 2D Gaussians, drawn at the flush as their 95%
    ellipses of n sides (`shapes.ellipse_polylines`), one line strip each."""

    def __init__(self, n: int) -> None:
        self.n = n

    def _arrow(self, values: np.ndarray) -> pa.Array:
        covs = values[:, 2:].reshape(-1, 2, 2)
        return _fixed_strips(ellipse_polylines(values[:, :2], covs, n=self.n, dtype=np.float32))

    def column(self) -> _Column:
        return _Column((6,), np.float64, self._arrow)


class Circles(Kind):
    """(m, 3) [x, y, r]: m circles, drawn at the flush as closed line strips of n sides
    (`shapes.circle_polylines`)."""

    def __init__(self, n: int = 48) -> None:
        self.n = n

    def _arrow(self, values: np.ndarray) -> pa.Array:
        return _fixed_strips(circle_polylines(values, n=self.n))

    def column(self) -> _Column:
        return _Column((3,), np.float64, self._arrow)


def _fixed_strips(drawn: np.ndarray) -> pa.Array:
    """(m, n, 2) m strips of n points as rerun's LineStrip2D components."""
    m, n = drawn.shape[:2]
    points = drawn.reshape(-1, 2).astype(np.float32, copy=False)
    return rows._STRIPS.arrow((points, np.full(m, n, np.int32)))


class Pairs(Kind):
    """(m, 4) [ax, ay, bx, by]: m two-point line strips (segments from a to b), as float32:
    the rows' values are the strips' points one after the other (associations, lines)."""

    def column(self) -> _Column:
        return _Column((4,), np.float32, _pairs_arrow)


def _pairs_arrow(values: np.ndarray) -> pa.Array:
    return rows._STRIPS.arrow((values.reshape(-1, 2), np.full(len(values), 2, np.int32)))


class Strips(Kind):
    """(points (P, 2), lengths (m,)): m line strips one after the other (`strips`)."""

    def column(self) -> _StripsColumn:
        return _StripsColumn()


class _StripsColumn:
    __slots__ = ("lengths", "points", "strip_lengths")

    def __init__(self) -> None:
        self.points = _Grow((2,), np.float32)
        self.strip_lengths = _Grow((), np.int32)
        self.lengths: list[int] = []

    def put(self, value) -> None:
        points, lengths = value
        self.points.put(points)
        self.lengths.append(self.strip_lengths.put(lengths))

    def put_rows(self, value) -> None:
        """Rows of one strip each: (points, lengths (n,)), strip i of row i."""
        points, lengths = value
        self.points.put(points)
        self.lengths.extend([1] * self.strip_lengths.put(lengths))

    def take(self) -> tuple[pa.Array, np.ndarray]:
        data = (self.points.take(), self.strip_lengths.take())
        lengths, self.lengths = self.lengths, []
        return rows._STRIPS.arrow(data), _offsets(lengths)


_NO_STRIPS = (np.zeros((0, 2)), np.zeros(0, np.int32))  # (read, never written: `put` copies)


def strips(pieces) -> tuple[np.ndarray, np.ndarray]:
    """A `Strips` value: a list of (n_i, 2) arrays, or one (m, n, 2) array of m strips."""
    if not len(pieces):
        return _NO_STRIPS
    if isinstance(pieces, np.ndarray) and pieces.ndim == 3:
        m, n = pieces.shape[:2]
        return pieces.reshape(-1, 2), np.full(m, n, np.int32)
    if len(pieces) == 1:
        return pieces[0], np.array([len(pieces[0])], np.int32)
    lengths = np.array([len(p) for p in pieces], np.int32)
    points = np.concatenate(pieces).reshape(-1, 2) if len(lengths) else np.zeros((0, 2))
    return points, lengths


class Texts(Kind):
    """A list of m texts."""

    def column(self) -> _TextsColumn:
        return _TextsColumn()


class _TextsColumn:
    __slots__ = ("lengths", "texts")

    def __init__(self) -> None:
        self.texts: list[str] = []
        self.lengths: list[int] = []

    def put(self, value) -> None:
        self.texts.extend(value)
        self.lengths.append(len(value))

    def take(self) -> tuple[pa.Array, np.ndarray]:
        texts, self.texts = self.texts, []
        lengths, self.lengths = self.lengths, []
        return pa.array(texts, pa.string()), _offsets(lengths)


class Const:
    """A component with the same value in every row (`rows.Field`: `rows.color`,
    `rows.radii_ui`); a row gives no value for it."""

    def __init__(self, field: rows.Field) -> None:
        self.field = field

    def take(self, n_rows: int) -> tuple[pa.Array, np.ndarray]:
        kind, data = self.field.kind, self.field.data
        m = kind.length(data)
        joined = kind.join([data] * n_rows) if n_rows else kind.join([data])[:0]
        return kind.arrow(joined), np.arange(0, m * n_rows + 1, m, dtype=np.int32)


class Spec:
    """The components of an entity's rows: `archetype` (a rerun archetype class, e.g.
    `rr.Points2D`) and its fields in order, each a `Kind` (a value each row) or a `Const`.
    A row's values are given in the order of its `Kind` fields."""

    def __init__(self, archetype: type, **fields: Kind | Const) -> None:
        self.fields = [(rows._descriptor(archetype, f), k) for f, k in fields.items()]

    def table(self) -> Table:
        return Table(self)


class Table:
    """An entity's rows of a batch (`Spec`), as columns: `add` a row, `take` them all."""

    __slots__ = ("columns", "scan", "spec", "time")

    def __init__(self, spec: Spec) -> None:
        self.spec = spec
        self.columns = [k.column() for _, k in spec.fields if not isinstance(k, Const)]
        self.scan: list[int] = []  # the rows' scans and times (lists: cheaper to append to)
        self.time: list[float] = []  # NaN: a row without time

    @property
    def n(self) -> int:
        """Rows added since the last take."""
        return len(self.scan)

    def add(self, k: int, stamp_s: float | None, values: tuple) -> None:
        """A row at scan `k` and time `stamp_s` (s, or None), with the values of the Kind
        fields in order."""
        self.scan.append(k)
        self.time.append(np.nan if stamp_s is None else stamp_s)
        for column, value in zip(self.columns, values):
            column.put(value)

    def add_rows(self, scan: list[int], stamps_s: list[float], values: tuple) -> None:
        """Rows at the scans `scan` and times `stamps_s` (s, NaN for none), each with one
        instance a field: the values of the Kind fields in order, each those of every row
        (n rows' values, as `put` takes one row's; a `Strips` field: one strip a row). Only
        the kinds of fixed shape (`Vectors`, `AxisZ`, `Floats`, `Formatted`, `Ellipses`,
        `Pairs`, ...) and `Strips` take rows so."""
        self.scan.extend(scan)
        self.time.extend(stamps_s)
        for column, value in zip(self.columns, values):
            column.put_rows(value)

    def take(self) -> tuple[np.ndarray, np.ndarray, list]:
        """(scan (n,) int64, time (n,) s with NaN for none, [(descriptor, arrow array of every
        row's values, int32 offsets (n + 1,))]) of the rows added since the last take."""
        n = len(self.scan)
        kept = iter(self.columns)
        out = []
        for descriptor, kind in self.spec.fields:
            array, offsets = kind.take(n) if isinstance(kind, Const) else next(kept).take()
            out.append((descriptor, array, offsets))
        scan, self.scan = np.array(self.scan, np.int64), []
        stamps, self.time = np.array(self.time, np.float64), []
        return scan, stamps, out
