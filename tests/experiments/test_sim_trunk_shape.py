"""Simulated trunks that are not circles (experiments/sim/shapes.py, `trunk_shape` in a scene
file): exact geometry, the truth tables kept, circles untouched, clear errors, and the property
they exist for: the fitted centre's offset depends on the side the trunk is seen from and
persists within a pass (experiments/eval/centre_offsets.py)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from experiments.errors import ConfigError, DataError
from experiments.eval.centre_offsets import pass_statistics, sighting_offsets
from experiments.sim import (
    CircleObject,
    Scene,
    load_scene,
    raycast,
    raycast_dense,
    scene_from_dict,
    sensor_preset,
    simulate_scan,
    simulate_sequence,
)
from experiments.sim.scene import scenes_dir, shape_trunks
from experiments.sim.shapes import TrunkShape, polygon_area_centroid, trunk_outline
from features import extract_features
from slam import se2

OVAL = TrunkShape(aspect=1.3, lobes=3, lobe_amplitude=0.05, seed=4)


def tree_park_dict() -> dict:
    return json.loads((scenes_dir() / "tree_park.json").read_text(encoding="utf-8"))


def test_outline_has_the_circles_area_and_centroid_and_the_truth_tables_are_kept():
    base = load_scene("tree_park")
    shaped = shape_trunks(base, OVAL)
    assert np.array_equal(shaped.truth_landmarks, base.truth_landmarks)
    assert [c.name for c in shaped.circles] == [c.name for c in base.circles]
    for c in shaped.circles:
        area, centroid = polygon_area_centroid(c.outline_xy)
        assert area == pytest.approx(math.pi * c.radius_m**2, rel=1e-12)
        assert np.allclose(centroid, c.center_xy, atol=1e-12)
        far = np.hypot(*(c.outline_xy - c.center_xy).T)
        assert far.max() / far.min() > 1.3  # not a circle
    # each trunk draws its own orientation: the outlines are not copies of one another
    unit = [(c.outline_xy - c.center_xy) / c.radius_m for c in shaped.circles]
    assert not any(np.allclose(u, unit[0]) for u in unit[1:])


def test_a_beam_along_the_long_axis_meets_the_ellipse_at_its_vertex():
    r, aspect, n = 0.3, 1.5, 180
    shape = TrunkShape(aspect=aspect, n_vertices=n)
    for orientation in (0.0, 0.7, 2.0):
        outline = trunk_outline((2.0, -1.0), r, shape, orientation, 0.0)
        scene = Scene(circles=(CircleObject("t", (2.0, -1.0), r, outline_xy=outline),))
        u = np.array([math.cos(orientation), math.sin(orientation)])
        origin = np.array([2.0, -1.0]) + 10.0 * u
        rng, lab = raycast(scene, origin, [orientation + math.pi])
        # the inscribed polygon's area is n/2 sin(2 pi / n) a b; it is scaled to pi r^2
        half_axis = r * math.sqrt(aspect) * math.sqrt(math.pi / (n / 2 * math.sin(2 * math.pi / n)))
        assert rng[0] == pytest.approx(10.0 - half_axis, abs=1e-12)
        assert lab[0] == 0


def test_shaped_scene_raycast_equals_the_dense_oracle_and_hits_the_outline():
    scene = shape_trunks(load_scene("tree_park"), OVAL)
    a = np.linspace(-math.pi, math.pi, 720, endpoint=False)
    for origin in scene.scan_positions[::3, :2]:
        r1, l1 = raycast(scene, origin, a)
        r2, l2 = raycast_dense(scene, origin, a)
        assert np.array_equal(l1, l2)
        assert np.allclose(r1[np.isfinite(r1)], r2[np.isfinite(r1)], atol=1e-9, rtol=0)
        on = l1 < len(scene.circles)
        on &= l1 >= 0
        assert on.sum() > 20
        for k in np.flatnonzero(on):
            p = origin + r1[k] * np.array([math.cos(a[k]), math.sin(a[k])])
            seg = scene.circles[l1[k]].segments_xy
            e = seg[:, 1] - seg[:, 0]
            s = np.clip(np.sum((p - seg[:, 0]) * e, axis=1) / np.sum(e * e, axis=1), 0, 1)
            assert np.min(np.hypot(*(seg[:, 0] + s[:, None] * e - p).T)) < 1e-9


def test_a_circle_shape_leaves_the_scene_and_its_scans_identical():
    base = load_scene("tree_park")
    assert shape_trunks(base, TrunkShape()) is base
    data = tree_park_dict() | {"trunk_shape": {"aspect": 1, "seed": 3, "note": "a circle"}}
    same = scene_from_dict(data)
    assert all(c.outline_xy is None for c in same.circles)
    sensor = sensor_preset("lms200")
    for pose in base.scan_positions[:4]:
        r0, l0 = simulate_scan(base, pose, sensor, np.random.default_rng(5))
        r1, l1 = simulate_scan(same, pose, sensor, np.random.default_rng(5))
        assert np.array_equal(r0, r1, equal_nan=True) and np.array_equal(l0, l1)


def test_a_scene_file_trunk_shape_shapes_only_the_trunks():
    data = tree_park_dict()
    data["circles"].append({"name": "p", "kind": "pillar", "center_xy": [0, 30], "radius_m": 0.2})
    data["trunk_shape"] = {"aspect": 1.3, "lobes": 3, "lobe_amplitude": 0.05, "seed": 4}
    scene = scene_from_dict(data)
    kinds = [(c.kind, c.outline_xy is None) for c in scene.circles]
    assert kinds == [("trunk", False)] * 8 + [("pillar", True)]
    ref = shape_trunks(load_scene("tree_park"), OVAL)
    assert all(
        np.array_equal(a.outline_xy, b.outline_xy) for a, b in zip(scene.circles, ref.circles)
    )


@pytest.mark.parametrize(
    ("shape", "message"),
    [
        ({"aspect": 0.9}, "aspect: must be in [1, 4]"),
        ({"aspect": float("nan")}, "aspect: must be a finite number"),
        ({"aspect": "1.2"}, "aspect: must be a finite number"),
        ({"aspect": 1.2, "lobes": -1}, "lobes: must be a whole number in [0, 32]"),
        ({"lobes": 2.5}, "lobes: must be a whole number"),
        ({"lobe_amplitude": 0.1}, "lobe_amplitude: 0.1 needs lobes >= 1"),
        ({"lobes": 3, "lobe_amplitude": 0.6}, "lobe_amplitude: must be in [0, 0.5]"),
        ({"seed": True}, "seed: must be a whole number"),
        ({"n_vertices": 8}, "n_vertices: must be a whole number in [16, 4096]"),
    ],
)
def test_bad_shapes_are_refused_naming_the_field(shape, message):
    with pytest.raises(ConfigError, match=f"TrunkShape.{message}".replace("[", r"\[")):
        TrunkShape(**shape)
    with pytest.raises(
        DataError, match=r"x\.json: trunk_shape: TrunkShape\." + message.split(":")[0]
    ):
        scene_from_dict(tree_park_dict() | {"trunk_shape": shape}, source="x.json")


def test_unknown_trunk_shape_key_is_refused():
    with pytest.raises(DataError, match=r"trunk_shape: unknown key\(s\) \['aspekt'\]"):
        scene_from_dict(tree_park_dict() | {"trunk_shape": {"aspekt": 1.3}})
    with pytest.raises(DataError, match="trunk_shape: must be a JSON object"):
        scene_from_dict(tree_park_dict() | {"trunk_shape": 1.3})
    with pytest.raises(ConfigError, match="expected a TrunkShape"):
        shape_trunks(load_scene("tree_park"), {"aspect": 1.3})


def _two_passes(aspect: float, seed: int) -> dict:
    """One trunk (r 0.3 m, long axis along x) passed from the south, then (after a gap) from
    the east; the geometric fit's centre offsets against the truth, per sighting."""
    shape = TrunkShape(aspect=aspect)
    outline = None if aspect == 1 else trunk_outline((0.0, 0.0), 0.3, shape, 0.0, 0.0)
    scene = Scene(circles=(CircleObject("t", (0.0, 0.0), 0.3, outline_xy=outline),))
    s = np.linspace(-3.0, 3.0, 31)
    south = np.stack([s, np.full_like(s, -6.0), np.full_like(s, math.pi / 2)], axis=1)
    east = np.stack([np.full_like(s, 6.0), s, np.full_like(s, math.pi)], axis=1)
    t = np.concatenate([0.2 * np.arange(31), 20.0 + 0.2 * np.arange(31)])
    seq = simulate_sequence(
        scene, np.vstack([south, east]), sensor_preset("lms200"), np.random.default_rng(seed), t
    )
    feats = [extract_features(seq.scan(k), "geometric") for k in range(seq.n_scans)]
    laser = np.array([se2.compose(p, seq.laser_pose) for p in seq.truth_pose])
    return sighting_offsets(seq, feats, laser)


def test_a_non_circular_trunks_fitted_centre_depends_on_the_view_and_persists_in_a_pass():
    oval = _two_passes(1.5, seed=1)
    circle = _two_passes(1.0, seed=1)
    for s in (oval, circle):
        assert s["t"].size >= 60  # nearly every scan of both passes finds the trunk
    south, east = oval["t"] < 10, oval["t"] > 10
    # seen across its long axis the flat side looks like a big circle (centre pushed away);
    # seen end on, the sharp end like a small one (centre pulled in)
    assert oval["offset"][south, 0].mean() > 0.1
    assert oval["offset"][east, 0].mean() < -0.05
    for part in (circle["t"] < 10, circle["t"] > 10):
        assert abs(circle["offset"][part, 0].mean()) < 0.01
    so, sc = pass_statistics(oval)["range"], pass_statistics(circle)["range"]
    assert so.passes == sc.passes == 2
    assert so.pass_sd_m > 0.05 and so.lag1 > 0.7 and so.share > 0.8
    assert sc.pass_sd_m < 0.01 and abs(sc.lag1) < 0.3
