"""Rerun rows built straight as arrow arrays, for the entities a recording logs at every scan.

Rerun's archetypes (`rr.Points2D(...)`, `rr.LineStrips2D(...)`) convert each field in Python, a
strip or a colour at a time; at 15 entities a scan over a 7,249-scan Victoria Park run that
conversion was most of what a recording cost. `row` makes the same component batches (rerun's
descriptors, rerun's arrow types, the same values) from numpy arrays in a few vectorised
calls; `tests/experiments/test_recording_rows.py` checks each builder against rerun's own
conversion. A row keeps its values as numpy until it is sent, and `columns` joins the rows of
a batch of scans into one arrow array a component. This module does not import rerun (`viz`
does, and passes its archetype classes). A row goes wherever an archetype goes:
`RecordingStream.log`, or `viz._Batch`.
"""

from __future__ import annotations

import functools

import numpy as np
import pyarrow as pa  # rerun's own dependency: its columns are arrow arrays
import pyarrow.compute as pc

__all__ = [
    "Described",
    "Field",
    "Row",
    "axis_angles_z",
    "color",
    "colors",
    "columns",
    "id_labels",
    "labels",
    "radii_ui",
    "row",
    "strips",
    "vectors",
]

_F32 = pa.field("item", pa.float32(), nullable=False)
_VEC = {n: pa.list_(_F32, n) for n in (2, 3)}
_STRIP2 = pa.list_(pa.field("item", _VEC[2], nullable=False))
_AXIS_ANGLE = pa.struct(
    [pa.field("axis", _VEC[3], nullable=False), pa.field("angle", pa.float32(), nullable=False)]
)


class Described:
    """An arrow array with its component's descriptor (what `rr.log`, `rr.ComponentColumn`
    and `viz._Batch` read from a component batch)."""

    __slots__ = ("_array", "_descriptor")

    def __init__(self, descriptor, array) -> None:
        self._descriptor = descriptor
        self._array = array

    def as_arrow_array(self):
        return self._array

    def component_descriptor(self):
        return self._descriptor


# A field's values are kept as numpy until they are sent: the rows of a batch of scans become
# one arrow array a component (`columns`), not one a row. Each kind says how many instances
# its values hold, how the values of several rows join, and what arrow array they make.


class _Kind:
    def length(self, data) -> int:
        return len(data)

    def join(self, datas: list):
        return np.concatenate(datas)

    def arrow(self, data) -> pa.Array:
        raise NotImplementedError


class _Vectors(_Kind):
    """(n, d) float32: rerun's Vec2D/Vec3D components (positions, translations)."""

    def arrow(self, data) -> pa.Array:
        return pa.FixedSizeListArray.from_arrays(
            pa.array(data.reshape(-1)), type=_VEC[data.shape[1]]
        )


class _Plain(_Kind):
    """(n,) numbers of one arrow type (float32 radii, uint32 colours)."""

    def __init__(self, type_) -> None:
        self.type = type_

    def arrow(self, data) -> pa.Array:
        return pa.array(data, self.type)


class _Texts(_Kind):
    def join(self, datas: list):
        return [t for d in datas for t in d]

    def arrow(self, data) -> pa.Array:
        return pa.array(data, pa.string())


class _IdLabels(_Kind):
    """(n,) int64 ids labelled `prefix` + id ("L12"), the text made in one call a batch."""

    def __init__(self, prefix: str) -> None:
        self.prefix = pa.scalar(prefix, pa.string())

    def arrow(self, data) -> pa.Array:
        return pc.binary_join_element_wise(self.prefix, pc.cast(pa.array(data), pa.string()), "")


class _Strips(_Kind):
    """(points (P, 2) float32, lengths (m,) int32): m strips, one after the other."""

    def length(self, data) -> int:
        return len(data[1])

    def join(self, datas: list):
        return np.concatenate([d[0] for d in datas]), np.concatenate([d[1] for d in datas])

    def arrow(self, data) -> pa.Array:
        points, lengths = data
        offsets = np.zeros(len(lengths) + 1, np.int32)
        np.cumsum(lengths, out=offsets[1:])
        return pa.ListArray.from_arrays(
            pa.array(offsets), _VECTORS.arrow(points.reshape(-1, 2)), type=_STRIP2
        )


class _AxisZ(_Kind):
    """(n,) float32 angles: rotations about z as rerun's RotationAxisAngle components."""

    def arrow(self, data) -> pa.Array:
        axis = np.zeros((len(data), 3), np.float32)
        axis[:, 2] = 1.0
        return pa.StructArray.from_arrays(
            [_VECTORS.arrow(axis), pa.array(data)], fields=list(_AXIS_ANGLE)
        )


class _Arrow(_Kind):
    """An arrow array made elsewhere (a rerun archetype's component batch)."""

    def join(self, datas: list):
        return pa.concat_arrays(datas)

    def arrow(self, data) -> pa.Array:
        return data


_VECTORS, _F32S, _U32S, _TEXTS = _Vectors(), _Plain(pa.float32()), _Plain(pa.uint32()), _Texts()
_STRIPS, _AXIS_Z, _ARROW = _Strips(), _AxisZ(), _Arrow()


class Field:
    """One component's values in a row, as numpy (`kind` makes them arrow)."""

    __slots__ = ("data", "kind")

    def __init__(self, kind: _Kind, data) -> None:
        self.kind = kind
        self.data = data


class Row:
    """One archetype's components at one time: (descriptor, Field) pairs. It has
    `as_component_batches`, as an archetype has."""

    __slots__ = ("fields",)

    def __init__(self, fields: list) -> None:
        self.fields = fields

    @classmethod
    def of(cls, archetype) -> Row:
        """The row of a rerun archetype (or a Row itself)."""
        if isinstance(archetype, Row):
            return archetype
        return cls(
            [
                (b.component_descriptor(), Field(_ARROW, b.as_arrow_array()))
                for b in archetype.as_component_batches()
            ]
        )

    def as_component_batches(self) -> list:
        return [Described(d, f.kind.arrow(f.data)) for d, f in self.fields]


def columns(rows: list[Row]) -> list | None:
    """The rows of one entity as columns: [(descriptor, arrow array, lengths)], a component's
    values of every row in one array and the number of them each row holds. None when the
    rows do not all have the same components (they are then logged one at a time)."""
    first = [d for d, _ in rows[0].fields]
    out = []
    for i, d in enumerate(first):
        fields = []
        for r in rows:
            if len(r.fields) != len(first) or r.fields[i][0] != d:
                return None
            fields.append(r.fields[i][1])
        kind = fields[0].kind
        if any(f.kind is not kind for f in fields):
            return None
        datas = [f.data for f in fields]
        out.append((d, kind.arrow(kind.join(datas)), [kind.length(x) for x in datas]))
    return out


@functools.cache
def _descriptor(archetype: type, field: str):
    return getattr(archetype, f"descriptor_{field}")()


def row(archetype: type, **fields: Field) -> Row:
    """A row of the rerun archetype class `archetype` (`rr.Points2D`; only `viz` imports
    rerun) whose fields are given by the builders below."""
    return Row([(_descriptor(archetype, f), v) for f, v in fields.items()])


def vectors(xy) -> Field:
    """(n, 2) or (n, 3) floats as rerun's Vec2D/Vec3D components (positions, translations)."""
    xy = np.asarray(xy, np.float32)
    return Field(_VECTORS, xy.reshape(-1, xy.shape[-1]))


def strips(pieces) -> Field:
    """Line strips, each (n_i, 2): a list of arrays or one (m, n, 2) array of m strips."""
    if isinstance(pieces, np.ndarray) and pieces.ndim == 3:
        m, n = pieces.shape[:2]
        lengths = np.full(m, n, np.int32)
        points = pieces.reshape(-1, 2)
    else:
        lengths = np.array([len(p) for p in pieces], np.int32)
        points = np.concatenate(pieces).reshape(-1, 2) if len(lengths) else np.zeros((0, 2))
    return Field(_STRIPS, (points.astype(np.float32), lengths))


def axis_angles_z(radians) -> Field:
    """Rotations about z by `radians` (n,) as rerun's RotationAxisAngle components."""
    return Field(_AXIS_Z, np.asarray(radians, np.float32).reshape(-1))


def colors(rgb) -> Field:
    """(n, 3) or (3,) uint8 RGB as rerun's Color components (opaque RGBA packed in a u32)."""
    rgb = np.asarray(rgb, np.uint32).reshape(-1, 3)
    packed = (rgb[:, 0] << 24) | (rgb[:, 1] << 16) | (rgb[:, 2] << 8) | np.uint32(255)
    return Field(_U32S, packed)


@functools.cache
def color(r: int, g: int, b: int) -> Field:
    """One colour (`colors`), made once."""
    return colors([r, g, b])


@functools.cache
def radii_ui(points: float) -> Field:
    """One radius in UI points (`rr.Radius.ui_points`: rerun stores it negated), made once."""
    return Field(_F32S, np.array([-float(points)], np.float32))


def labels(texts) -> Field:
    """Text labels as rerun's Text components."""
    return Field(_TEXTS, list(texts))


@functools.cache
def _id_labels(prefix: str) -> _IdLabels:
    return _IdLabels(prefix)


def id_labels(prefix: str, ids) -> Field:
    """The labels `prefix` + id of integer ids (`labels([f"{prefix}{i}" for i in ids])`)."""
    return Field(_id_labels(prefix), np.array(ids, np.int64).reshape(-1))
