"""The laser simulator (experiments/sim): exact geometry, sensor model, scenes, sequences."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from experiments.errors import DataError
from experiments.sim import (
    MIXED_LABEL,
    NO_RETURN_LABEL,
    BushObject,
    CircleObject,
    Scene,
    SensorModel,
    WallObject,
    laser_world_pose,
    list_scenes,
    load_scene,
    make_bush,
    raycast,
    raycast_dense,
    scene_from_dict,
    sensor_preset,
    simulate_scan,
    simulate_sequence,
    simulate_to_sequence,
)

EXACT = 1e-9  # m: tolerance for noise-free geometry


def exact_sensor(name: str = "pls200", **kw) -> SensorModel:
    return sensor_preset(name, range_sigma_m=0.0, quantisation_m=0.0, **kw)


def circle_range(origin, angles, center, r):
    """Textbook intersection: D cos(phi) - sqrt(r^2 - D^2 sin^2(phi)), NaN when missed."""
    v = np.asarray(center, float) - np.asarray(origin, float)
    D = np.hypot(*v)
    phi = np.asarray(angles) - math.atan2(v[1], v[0])
    h2 = r * r - (D * np.sin(phi)) ** 2
    hit = (h2 >= 0) & (np.cos(phi) > 0)
    return np.where(hit, D * np.cos(phi) - np.sqrt(np.where(hit, h2, 0.0)), np.nan)


def dist_to_polyline(pt, seg):
    """Distance from pt (2,) to the nearest of segments seg (S, 2, 2)."""
    p, e = seg[:, 0], seg[:, 1] - seg[:, 0]
    s = np.clip(np.sum((pt - p) * e, axis=1) / np.sum(e * e, axis=1), 0, 1)
    return float(np.min(np.hypot(*(p + s[:, None] * e - pt).T)))


def world_points(ranges, sensor, pose, laser_pose=(0, 0, 0)):
    lx, ly, lth = laser_world_pose(pose, laser_pose)
    a = lth + sensor.angles_rad
    return np.stack([lx + ranges * np.cos(a), ly + ranges * np.sin(a)], axis=1)


def assert_points_on_labelled_objects(scene, pts, labels, tol):
    """Every returned point lies on the surface of the object its label names."""
    n_checked = 0
    for pt, lab in zip(pts, labels, strict=True):
        if lab < 0:
            continue
        obj = scene.objects[lab]
        if isinstance(obj, CircleObject):
            d = abs(np.hypot(*(pt - obj.center_xy)) - obj.radius_m)
        else:
            d = dist_to_polyline(pt, obj.segments_xy)
        assert d < tol, (obj.name, d)
        n_checked += 1
    return n_checked


# ---- exact geometry ------------------------------------------------------------------------


def test_wall_at_known_distance_gives_exact_ranges_for_all_beams():
    # A wall on the line x cos(alpha) + y sin(alpha) = rho (world), long enough for every beam.
    alpha, rho = 0.4, 12.0
    n = np.array([math.cos(alpha), math.sin(alpha)])
    t = np.array([-n[1], n[0]])
    wall = WallObject("w", [rho * n - 1e4 * t, rho * n + 1e4 * t])
    scene = Scene(walls=(wall,))
    sensor = exact_sensor(max_range_m=math.inf)
    pose, laser_pose = (1.0, -2.0, 0.3), (0.7, 0.2, 0.1)
    r, lab = simulate_scan(scene, pose, sensor, np.random.default_rng(0), laser_pose=laser_pose)
    lx, ly, lth = laser_world_pose(pose, laser_pose)
    rho_laser = rho - (lx * n[0] + ly * n[1])  # distance of the line from the laser
    c = np.cos(lth + sensor.angles_rad - alpha)
    expected = np.where(c > 0, rho_laser / np.where(c > 0, c, 1.0), np.nan)
    expected[np.abs(expected * np.sin(lth + sensor.angles_rad - alpha)) > 1e4] = np.nan
    assert np.array_equal(np.isnan(r), np.isnan(expected))
    assert np.isfinite(r).sum() >= 300  # most of the 361 beams see the wall
    np.testing.assert_allclose(
        r[np.isfinite(r)], expected[np.isfinite(expected)], rtol=0, atol=EXACT
    )
    assert np.all(lab[np.isfinite(r)] == 0) and np.all(lab[np.isnan(r)] == NO_RETURN_LABEL)


def test_circle_ranges_equal_the_analytic_intersection():
    center, rad = (8.0, 3.0), 0.5
    scene = Scene(circles=(CircleObject("c", center, rad),))
    a = np.linspace(0.0, 0.8, 4001)
    r, lab = raycast(scene, (0.0, 0.0), a)
    expected = circle_range((0, 0), a, center, rad)
    hit = np.isfinite(expected)
    assert hit.sum() > 100
    assert np.array_equal(np.isfinite(r), hit)
    np.testing.assert_allclose(r[hit], expected[hit], rtol=0, atol=EXACT)
    assert np.all(lab[hit] == 0) and np.all(lab[~hit] == NO_RETURN_LABEL)
    assert np.all(np.isinf(r[~hit]))  # raycast itself reports +inf for "nothing hit"


def test_occlusion_nearest_hit_wins():
    scene = Scene(
        circles=(CircleObject("near", (5.0, 0.0), 0.4), CircleObject("far", (9.0, 0.3), 0.8)),
        walls=(WallObject("wall", [(15.0, -50.0), (15.0, 50.0)]),),
    )
    a = np.linspace(-0.3, 0.3, 1201)
    r, lab = raycast(scene, (0.0, 0.0), a)
    near = circle_range((0, 0), a, (5.0, 0.0), 0.4)
    far = circle_range((0, 0), a, (9.0, 0.3), 0.8)
    wall = 15.0 / np.cos(a)
    expected = np.fmin(np.fmin(near, far), wall)
    np.testing.assert_allclose(r, expected, rtol=0, atol=EXACT)
    want = np.where(np.isfinite(near), 0, np.where(np.isfinite(far), 1, 2))
    assert np.array_equal(lab, want)
    # All three are seen somewhere, and "far" is partly hidden behind "near".
    assert set(np.unique(lab)) == {0, 1, 2}
    assert np.sum(np.isfinite(far) & (lab == 0)) > 0


def test_sparse_raycast_equals_dense_oracle_on_random_scenes():
    rng = np.random.default_rng(7)
    for trial in range(60):
        circles = tuple(
            CircleObject(f"c{i}", rng.uniform(-20, 20, 2), rng.uniform(0.05, 2.0)) for i in range(8)
        )
        walls = tuple(
            WallObject(
                f"w{i}", rng.uniform(-25, 25, (int(rng.integers(2, 5)), 2)), closed=bool(i % 2)
            )
            for i in range(5)
        )
        bushes = tuple(
            BushObject(f"b{i}", make_bush(rng.uniform(-20, 20, 2), rng.uniform(0.3, 2), rng))
            for i in range(4)
        )
        scene = Scene(circles=circles, walls=walls, bushes=bushes)
        origins = [
            rng.uniform(-20, 20, 2),
            circles[0].center_xy,
            walls[0].points_xy[0],
            0.5 * (walls[1].points_xy[0] + walls[1].points_xy[1]),
        ]
        for o in origins:  # incl. inside a circle, at a wall's end and on a wall's line
            a = np.concatenate([rng.uniform(-7, 7, 400), np.linspace(-np.pi, np.pi, 721)])
            r1, l1 = raycast(scene, o, a)
            r2, l2 = raycast_dense(scene, o, a)
            fin = np.isfinite(r2)
            assert np.array_equal(np.isfinite(r1), fin), trial
            np.testing.assert_allclose(r1[fin], r2[fin], rtol=0, atol=EXACT)
            assert np.mean(l1 == l2) == 1.0, trial


def test_labels_name_the_surface_each_beam_hit():
    scene = load_scene("test_yard")
    sensor = exact_sensor(back_to_back=True)
    for pose in scene.scan_positions:
        r, lab = simulate_scan(scene, pose, sensor, np.random.default_rng(0))
        n = assert_points_on_labelled_objects(scene, world_points(r, sensor, pose), lab, EXACT)
        assert n > 500
    groups = scene.label_group(lab)
    assert {"circle", "wall", "bush", "none"} <= set(groups)
    assert set(scene.label_kind(lab)) <= {"trunk", "wall", "bush", "none"}
    assert scene.label_kind(np.array([0, 9, 13, -1, -2])).tolist() == [
        "trunk",
        "wall",
        "bush",
        "none",
        "mixed",
    ]
    assert scene.label_name(np.array([scene.label_of("t05")])).tolist() == ["t05"]
    with pytest.raises(ValueError, match="labels"):
        scene.label_kind(np.array([scene.n_objects]))


# ---- sensor model ----------------------------------------------------------------------------


def test_presets_and_beam_layout():
    pls = sensor_preset("pls200")
    assert (pls.n_beams, pls.max_range_m, pls.range_sigma_m, pls.quantisation_m) == (
        361,
        50.0,
        0.01,
        0.01,
    )
    np.testing.assert_allclose(np.degrees(pls.angles_rad[[0, 180, 360]]), [-90, 0, 90], atol=1e-12)
    assert sensor_preset("LMS200").max_range_m == 80.0
    assert sensor_preset("pls200", range_sigma_m=0.03).range_sigma_m == 0.03
    with pytest.raises(ValueError, match="unknown sensor"):
        sensor_preset("velodyne")
    with pytest.raises(ValueError, match="range_noise"):
        sensor_preset("pls200", range_noise=0.1)
    for kw, field in [
        (dict(fov_rad=0.0), "fov_rad"),
        (dict(fov_rad=1.0), "fov_rad"),  # not a whole number of increments
        (dict(range_sigma_m=-1.0), "range_sigma_m"),
        (dict(mixed_prob=1.5), "mixed_prob"),
        (dict(max_range_m=0.0), "max_range_m"),
        (dict(back_to_back=True, fov_rad=math.radians(90)), "fov_rad"),
    ]:
        with pytest.raises(ValueError, match=field):
            SensorModel(**kw)


def test_max_range_gives_no_return():
    far_wall = Scene(walls=(WallObject("w", [(60.0, -5.0), (60.0, 5.0)]),))
    r, lab = simulate_scan(far_wall, (0, 0, 0), exact_sensor("pls200"), np.random.default_rng(0))
    assert np.all(np.isnan(r)) and np.all(lab == NO_RETURN_LABEL)
    r, lab = simulate_scan(far_wall, (0, 0, 0), exact_sensor("lms200"), np.random.default_rng(0))
    assert np.sum(np.isfinite(r)) == np.sum(lab == 0) == 19  # +-4.76 deg at 0.5 deg
    # A reading at the maximum range is "no return" too.
    edge = Scene(walls=(WallObject("w", [(50.0, -0.1), (50.0, 0.1)]),))
    r, lab = simulate_scan(edge, (0, 0, 0), exact_sensor("pls200"), np.random.default_rng(0))
    assert np.all(np.isnan(r)) and np.all(lab == NO_RETURN_LABEL)


def test_quantisation_to_one_centimetre():
    scene = load_scene("test_yard")
    sensor = sensor_preset("pls200", back_to_back=True)  # sigma 1 cm, 1 cm steps
    r, _ = simulate_scan(scene, scene.scan_positions[0], sensor, np.random.default_rng(3))
    rf = r[np.isfinite(r)]
    assert rf.size > 550
    assert np.max(np.abs(rf / 0.01 - np.round(rf / 0.01))) < 1e-6
    # Without noise, quantisation moves a reading by at most half a step.
    exact = sensor_preset("pls200", back_to_back=True, range_sigma_m=0.0)
    rq, _ = simulate_scan(scene, scene.scan_positions[0], exact, np.random.default_rng(3))
    r0, _ = raycast(scene, scene.scan_positions[0, :2], exact.angles_rad)
    fin = np.isfinite(rq)
    assert np.max(np.abs(rq[fin] - r0[fin])) <= 0.005 + 1e-9


def test_noise_standard_deviation_matches_sigma():
    # 200 scans x 361 beams = 72,200 draws: the sample std's standard error is sigma / 380
    # (0.26 %); the tolerance is 2 %, the mean's is 4 standard errors.
    scene = Scene(walls=(WallObject("w", [(10.0, -1e3), (10.0, 1e3)]),))
    a = np.radians(np.arange(-90, 90.5, 0.5))
    truth = np.where(np.abs(a) < np.radians(89), 10.0 / np.cos(a), np.nan)
    rng = np.random.default_rng(11)
    for q, sigma, expected_std in [
        (0.0, 0.02, 0.02),
        (0.01, 0.01, math.sqrt(0.01**2 + 0.01**2 / 12)),
    ]:
        sensor = sensor_preset("pls200", range_sigma_m=sigma, quantisation_m=q, max_range_m=1e4)
        seq = simulate_sequence(scene, np.zeros((200, 3)), sensor, rng)
        err = (seq.scan_ranges - truth)[:, np.isfinite(truth)].ravel()
        assert err.size == 200 * 355
        assert abs(np.std(err) / expected_std - 1) < 0.02
        assert abs(np.mean(err)) < 4 * expected_std / math.sqrt(err.size)


def test_back_to_back_covers_360_degrees():
    room = Scene(walls=(WallObject("room", [(-8, -6), (12, -6), (12, 9), (-8, 9)], closed=True),))
    single = exact_sensor()
    both = exact_sensor(back_to_back=True)
    assert both.n_beams == 720 and both.angle_min_rad == -math.pi
    assert np.allclose(np.diff(both.angles_rad), math.radians(0.5))
    assert math.isclose(np.degrees(both.angles_rad[-1]), 179.5)
    pose = (1.0, 0.5, 0.7)
    r2, lab2 = simulate_scan(room, pose, both, np.random.default_rng(0))
    assert np.all(np.isfinite(r2)) and np.all(lab2 == 0)  # every direction sees a wall
    r1, _ = simulate_scan(room, pose, single, np.random.default_rng(0))
    assert np.isnan(r1).sum() == 0 and r1.size == 361
    np.testing.assert_allclose(r2[180:541], r1, rtol=0, atol=EXACT)  # front half == one sensor
    n = assert_points_on_labelled_objects(room, world_points(r2, both, pose), lab2, EXACT)
    assert n == 720


def test_mixed_returns_only_at_depth_jumps_and_between_the_surfaces():
    scene = load_scene("test_yard")
    pose = scene.scan_positions[0]
    base = exact_sensor(back_to_back=True)
    truth, _ = raycast(scene, pose[:2], pose[2] + base.angles_rad)
    truth[truth >= base.max_range_m] = np.inf
    nb = np.roll(truth, -1)  # next beam (the scan wraps around in 360 deg)
    with np.errstate(invalid="ignore"):
        jump_pair = (
            np.isfinite(truth) & np.isfinite(nb) & (np.abs(truth - nb) > base.mixed_min_jump_m)
        )
    at_jump = jump_pair | np.roll(jump_pair, 1)
    mixed_sensor = exact_sensor(back_to_back=True, mixed_prob=1.0)
    r, lab = simulate_scan(scene, pose, mixed_sensor, np.random.default_rng(5))
    mixed = lab == MIXED_LABEL
    assert jump_pair.sum() >= 10 and mixed.sum() >= 0.5 * jump_pair.sum()
    assert not np.any(mixed & ~at_jump)
    for k in np.nonzero(mixed)[0]:
        ok = False
        for j in ((k - 1) % 720, (k + 1) % 720):
            lo, hi = sorted((truth[k], truth[j]))
            ok |= (
                at_jump[j] and abs(truth[k] - truth[j]) > base.mixed_min_jump_m and lo <= r[k] <= hi
            )
        assert ok, k
    truth_nan = np.where(np.isfinite(truth), truth, np.nan)
    np.testing.assert_allclose(r[~mixed], truth_nan[~mixed], rtol=0, atol=EXACT)
    # Off by default; with noise, the beams left alone are exactly the mixed-free scan's.
    r0, lab0 = simulate_scan(
        scene, pose, sensor_preset("pls200", back_to_back=True), np.random.default_rng(9)
    )
    assert not np.any(lab0 == MIXED_LABEL)
    rm, labm = simulate_scan(
        scene,
        pose,
        sensor_preset("pls200", back_to_back=True, mixed_prob=0.3),
        np.random.default_rng(9),
    )
    keep = labm != MIXED_LABEL
    assert 0 < (~keep).sum() < at_jump.sum()
    np.testing.assert_array_equal(rm[keep], r0[keep])


def test_low_balusters_are_below_the_scan_plane():
    scene = load_scene("pillar_court")
    kinds = {o.name: o.kind for o in scene.objects}
    assert sorted(n for n, k in kinds.items() if k == "baluster") == [
        "baluster_east",
        "baluster_south",
    ]
    seen = set()
    for pose in scene.scan_positions:
        _, lab = simulate_scan(
            scene, pose, exact_sensor(back_to_back=True), np.random.default_rng(0)
        )
        seen |= set(scene.label_kind(lab))
    assert "baluster" not in seen and {"pillar", "wall", "bush"} <= seen
    low = exact_sensor(back_to_back=True, mount_height_m=0.5)
    _, lab = simulate_scan(scene, scene.scan_positions[3], low, np.random.default_rng(0))
    assert np.sum(scene.label_kind(lab) == "baluster") > 50


# ---- sequences --------------------------------------------------------------------------------


def test_simulate_sequence_fills_truth_consistently():
    scene = load_scene("test_yard")
    sensor = sensor_preset("pls200", range_sigma_m=0.0)
    poses = np.array([[0.0, 0.0, 0.0], [1.0, 0.5, 0.1], [2.0, 1.2, 0.25]])
    times = np.array([10.0, 10.2, 10.4])
    laser_pose = (0.5, -0.1, 0.02)
    seq = simulate_sequence(scene, poses, sensor, np.random.default_rng(1), times, laser_pose)
    assert seq.scan_ranges.shape == seq.scan_labels.shape == (3, 361)
    np.testing.assert_array_equal(seq.scan_t, times)
    np.testing.assert_array_equal(seq.truth_t, times)
    np.testing.assert_array_equal(seq.truth_pose, poses)
    np.testing.assert_array_equal(seq.truth_landmarks, scene.truth_landmarks)
    np.testing.assert_array_equal(seq.laser_pose, laser_pose)
    assert seq.truth_landmarks.shape == (9, 3) and seq.scan_max_range == 50.0
    assert (seq.scan_angle_min, seq.scan_angle_increment) == (
        sensor.angle_min_rad,
        sensor.angle_increment_rad,
    )
    assert np.array_equal(seq.scan_labels == NO_RETURN_LABEL, np.isnan(seq.scan_ranges))
    assert "test_yard" in seq.name
    for k in range(3):
        scan = seq.scan(k)
        np.testing.assert_array_equal(scan.angles_rad, sensor.angles_rad)
        # Beam points, through truth_pose and laser_pose, land on the labelled objects (1 cm
        # quantisation: within 5 mm along the beam).
        pts = world_points(scan.ranges_m, sensor, seq.truth_pose[k], seq.laser_pose)
        assert assert_points_on_labelled_objects(scene, pts, seq.scan_labels[k], 0.005 + 1e-9) > 250
        lab = seq.scan_labels[k]
        on_trunk = (lab >= 0) & (lab < 9)
        d = np.hypot(*(pts[on_trunk] - seq.truth_landmarks[lab[on_trunk], :2]).T)
        np.testing.assert_allclose(d, seq.truth_landmarks[lab[on_trunk], 2], atol=0.005 + 1e-9)
    with pytest.raises(ValueError, match="times_s"):
        simulate_sequence(scene, poses, sensor, np.random.default_rng(1), times_s=[0, 2, 1])


def test_simulate_to_sequence_for_the_cli():
    seq = simulate_to_sequence("pillar_court", None, back_to_back=True, seed=3)
    scene = load_scene("pillar_court")
    assert seq.scan_ranges.shape == (6, 720)
    np.testing.assert_array_equal(seq.truth_pose, scene.scan_positions)
    again = simulate_to_sequence("pillar_court", None, back_to_back=True, seed=3)
    np.testing.assert_array_equal(seq.scan_ranges, again.scan_ranges)
    other = simulate_to_sequence("pillar_court", None, back_to_back=True, seed=4)
    assert np.nanmax(np.abs(seq.scan_ranges - other.scan_ranges)) > 0.02
    one = simulate_to_sequence("test_yard", [0.0, 0.0, 0.0], sensor_name="lms200", noise_m=0.0)
    r0, _ = raycast(scene := load_scene("test_yard"), (0, 0), sensor_preset("lms200").angles_rad)
    fin = np.isfinite(one.scan_ranges[0])
    assert one.scan_ranges.shape == (1, 361) and one.scan_max_range == 80.0
    np.testing.assert_allclose(one.scan_ranges[0][fin], np.round(r0[fin], 2), atol=1e-9)
    assert scene.n_objects == 16


# ---- scenes ----------------------------------------------------------------------------------


def test_bundled_scenes(tmp_path):
    assert {"pillar_court", "test_yard", "tree_park"} <= set(list_scenes())
    court = load_scene("pillar_court")
    assert [c.name for c in court.circles] == list("abcdefghij")
    assert all(c.kind == "pillar" and 0.15 <= c.radius_m <= 0.4 for c in court.circles)
    assert court.scan_positions.shape == (6, 3) and court.description.startswith("Pillar court")
    sensor = exact_sensor(back_to_back=True)
    hits = np.zeros((6, 10), dtype=int)
    for s, pose in enumerate(court.scan_positions):
        _, lab = simulate_scan(court, pose, sensor, np.random.default_rng(0))
        hits[s] = np.bincount(lab[(lab >= 0) & (lab < 10)], minlength=10)
    assert np.all(hits.max(axis=0) >= 6)  # each pillar well seen from some position
    assert np.all(hits[[1, 3]][:, 3:7] >= 2)  # d, e, f, g at positions 2 and 4
    yard = load_scene("test_yard")
    radii = yard.truth_landmarks[:, 2]
    assert radii.min() == 0.1 and radii.max() == 0.6 and len(yard.bushes) == 3
    _, lab = simulate_scan(yard, yard.scan_positions[0], sensor, np.random.default_rng(0))
    assert np.all(np.bincount(lab[(lab >= 0) & (lab < 9)], minlength=9) >= 3)  # all trunks seen
    # A path works as well as a name.
    from experiments.sim.scene import scenes_dir

    mine = tmp_path / "my_yard.json"
    mine.write_text((scenes_dir() / "test_yard.json").read_text())
    assert load_scene(mine).n_objects == yard.n_objects


def _write(tmp_path, data) -> str:
    p = tmp_path / "s.json"
    p.write_text(json.dumps(data) if not isinstance(data, str) else data)
    return str(p)


C0 = {"name": "a", "center_xy": [0, 0]}


@pytest.mark.parametrize(
    "data, message",
    [
        ({"circles": [C0]}, r"circles\[0\]: missing required key 'radius_m'"),
        ({"circles": [{**C0, "radius_m": -1}]}, r"circles\[0\].radius_m"),
        ({"circles": [{**C0, "center_xy": [0], "radius_m": 1}]}, r"circles\[0\].center_xy"),
        ({"circles": [{**C0, "radius_m": 1, "kind": "tree"}]}, r"circles\[0\].kind"),
        ({"circles": [{**C0, "radius": 1}]}, r"unknown key\(s\) \['radius'\]"),
        ({"walls": [{"name": "w", "points_xy": [[0, 0]]}]}, r"walls\[0\].points_xy"),
        ({"walls": [{"name": "w", "points_xy": [[0, 0], [0, 0]]}]}, r"zero-length"),
        ({"walls": [{"points_xy": [[0, 0], [1, 0]]}]}, r"walls\[0\]: missing required key 'name'"),
        ({"bushes": [{"name": "b", "points_xy": [[0, 0], [1, 0], [2, 0]]}]}, r"zero area"),
        ({"walls": "nope"}, r"walls: must be a list"),
        ({"wall": []}, r"top level: unknown key"),
        ({"circles": [], "scan_positions": [[0, 0]]}, r"scan_positions\[0\]"),
        (
            {
                "circles": [{"name": "a", "center_xy": [0, 0], "radius_m": 1}],
                "walls": [{"name": "a", "points_xy": [[0, 0], [1, 0]]}],
            },
            r"unique",
        ),
        ({"description": "empty"}, r"needs at least one of"),
        ("{not json", r"not valid JSON"),
    ],
)
def test_scene_loading_errors_name_the_key(tmp_path, data, message):
    path = _write(tmp_path, data)
    with pytest.raises(DataError, match=message) as info:
        load_scene(path)
    assert str(path) in str(info.value)


def test_missing_scene_says_what_exists(tmp_path):
    with pytest.raises(DataError, match=r"scene 'no_such_scene' not found.*pillar_court"):
        load_scene("no_such_scene")
    with pytest.raises(DataError, match="scene file not found"):
        load_scene(tmp_path / "absent.json")
    assert isinstance(DataError("x"), ValueError)


def test_scene_from_dict_round_trip_and_object_validation():
    scene = scene_from_dict(
        {
            "circles": [
                {"name": "p", "kind": "pillar", "center_xy": [1, 2], "radius_m": 0.3, "height_m": 3}
            ],
            "scan_positions": [[0, 0, 0.5]],
        }
    )
    np.testing.assert_array_equal(scene.truth_landmarks, [[1, 2, 0.3]])
    assert scene.circles[0].height_m == 3.0 and scene.scan_position_names == ("1",)
    with pytest.raises(ValueError, match="radius_m"):
        CircleObject("c", (0, 0), 0.0)
    with pytest.raises(ValueError, match="center_xy"):
        CircleObject("c", (0, np.nan), 1.0)
    with pytest.raises(ValueError, match="scan_positions"):
        Scene(scan_positions=np.zeros((2, 2)))
