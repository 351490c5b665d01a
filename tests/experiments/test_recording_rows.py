"""`experiments.render.rows`: the rows a recording logs at every scan, built as arrow arrays,
are the component batches rerun's own archetypes make from the same values (descriptors, arrow
types and values)."""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import pytest
import rerun as rr

from experiments.render import rows


def _batches(archetype) -> dict:
    return {str(b.component_descriptor()): b for b in archetype.as_component_batches()}


def _same(ours: rows.Row, theirs) -> None:
    a, b = _batches(ours), _batches(theirs)
    assert a.keys() == b.keys()
    for name in a:
        assert a[name].component_descriptor() == b[name].component_descriptor()
        x, y = a[name].as_arrow_array(), b[name].as_arrow_array()
        assert x.type == y.type, name
        assert x.equals(y), name


RNG = np.random.default_rng(0)


def test_points_with_labels_colour_and_radius():
    xy = RNG.normal(size=(7, 2)) * 100
    ids = [f"L{i}" for i in range(7)]
    ours = rows.row(
        rr.Points2D,
        positions=rows.vectors(xy),
        radii=rows.radii_ui(3.0),
        colors=rows.color(40, 200, 90),
        labels=rows.labels(ids),
    )
    theirs = rr.Points2D(xy, radii=rr.Radius.ui_points(3.0), colors=[[40, 200, 90]], labels=ids)
    _same(ours, theirs)
    ours = rows.row(
        rr.Points2D,
        positions=rows.vectors(xy),
        radii=rows.radii_ui(3.0),
        colors=rows.color(40, 200, 90),
        labels=rows.id_labels("L", np.arange(7)),
    )
    _same(ours, theirs)


@pytest.mark.parametrize("shape", ["array", "list", "empty"])
def test_strips_of_one_length_or_many(shape):
    if shape == "array":
        pieces = RNG.normal(size=(5, 41, 2))
    elif shape == "list":
        pieces = [RNG.normal(size=(n, 2)) for n in (1, 2, 9, 3)]
    else:
        pieces = []
    kinds = np.array([[255, 150, 40], [60, 120, 255], [170, 105, 60], [1, 2, 3], [9, 9, 9]])
    kinds = kinds[: len(pieces)]
    ours = rows.row(
        rr.LineStrips2D,
        strips=rows.strips(pieces),
        radii=rows.radii_ui(1.5),
        colors=rows.colors(kinds),
    )
    theirs = rr.LineStrips2D(list(pieces), colors=kinds, radii=rr.Radius.ui_points(1.5))
    _same(ours, theirs)


def test_a_pose_as_translation_and_rotation_about_z():
    x, y, th = 12.5, -3.25, 2.9
    ours = rows.row(
        rr.Transform3D,
        translation=rows.vectors([[x, y, 0.0]]),
        rotation_axis_angle=rows.axis_angles_z([th]),
    )
    theirs = rr.Transform3D(
        translation=[x, y, 0.0], rotation=rr.RotationAxisAngle(axis=[0, 0, 1], radians=th)
    )
    _same(ours, theirs)


def test_rows_joined_as_columns_are_the_rows_one_after_the_other():
    """A batch of scans' rows of one entity: one arrow array a component, holding each row's
    values in turn, with the number each row holds; rows with other components: None."""
    pieces = [RNG.normal(size=(n, 3, 2)) for n in (2, 0, 5)]
    names = [["a", "b"], [], ["c", "d", "e", "f", "g"]]

    def strips_row(p, t):
        return rows.row(
            rr.LineStrips2D,
            strips=rows.strips(p),
            colors=rows.color(1, 2, 3),
            labels=rows.labels(t),
        )

    batch = [strips_row(p, t) for p, t in zip(pieces, names)]
    cols = rows.columns(batch)
    assert [str(d) for d, _, _ in cols] == [
        "LineStrips2D:strips",
        "LineStrips2D:colors",
        "LineStrips2D:labels",
    ]
    for (_, array, lengths), i in zip(cols, range(3)):
        each = [r.as_component_batches()[i].as_arrow_array() for r in batch]
        assert lengths == [len(a) for a in each]
        assert array.equals(pa.concat_arrays(each))
    assert cols[0][2] == [2, 0, 5]
    scalars = rows.columns([rows.Row.of(rr.Scalars([1.0, 2.0])), rows.Row.of(rr.Scalars([3.0]))])
    assert scalars[0][1].to_pylist() == [1.0, 2.0, 3.0] and scalars[0][2] == [2, 1]
    no_labels = rows.row(rr.LineStrips2D, strips=rows.strips(pieces[0]), colors=rows.color(1, 2, 3))
    assert rows.columns([batch[0], no_labels]) is None
