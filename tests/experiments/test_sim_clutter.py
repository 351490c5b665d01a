"""The clutter of real data in the simulated park (`experiments.sim.clutter`) and the per-class
map figures (`experiments.paper.sim_clutter`)."""

import math

import numpy as np
import pytest

from experiments.paper.sim_clutter import CLASSES, _map_figures, clutter_trial, summary_records
from experiments.sim import load_scene, sensor_preset, simulate_scan
from experiments.sim.clutter import (
    CAR_LENGTH_M,
    CAR_WIDTH_M,
    CLUTTER,
    LEG_GAP_M,
    car_outline,
    clutter_park,
)


def test_the_clutter_park_keeps_the_tree_parks_objects_and_labels():
    base, sc = load_scene("tree_park"), clutter_park()
    n = len(base.circles)
    for a, b in zip(base.objects, sc.objects[:n]):
        assert a.name == b.name and a.kind == b.kind
    np.testing.assert_array_equal(sc.truth_landmarks[:n], base.truth_landmarks)
    np.testing.assert_array_equal(sc.truth_trunks, np.arange(n))  # posts and legs are not trees
    np.testing.assert_array_equal(base.truth_trunks, np.arange(n))
    kinds = [o.kind for o in sc.objects]
    assert kinds.count("post") == len(CLUTTER["posts"])
    assert kinds.count("leg") == 2 * len(CLUTTER["people"])
    assert kinds.count("car") == len(CLUTTER["cars"])
    assert kinds.count("bush") == len(base.bushes) + len(CLUTTER["bushes"])


def test_a_car_is_a_rectangle_of_a_family_cars_size_and_legs_a_pair():
    c = car_outline((0.0, 0.0), math.radians(30.0))
    sides = np.hypot(*(np.roll(c, -1, axis=0) - c).T)
    np.testing.assert_allclose(sorted(sides), [CAR_WIDTH_M] * 2 + [CAR_LENGTH_M] * 2)
    sc = clutter_park()
    left, right = (sc.circles[sc.label_of(f"H1{s}")] for s in "LR")
    assert np.hypot(*(left.center_xy - right.center_xy)) == pytest.approx(LEG_GAP_M, abs=1e-12)


def test_the_beams_that_hit_a_car_lie_on_its_outline_and_say_car():
    sc = clutter_park()
    sensor = sensor_preset("lms200", range_sigma_m=0.0, quantisation_m=0.0)
    pose = np.array([4.3, -5.0, -math.pi / 2])  # on the route, facing the parked cars
    r, lab = simulate_scan(sc, pose, sensor, np.random.default_rng(0))
    car = sc.label_kind(lab) == "car"
    assert car.sum() >= 10
    pts = pose[:2] + r[car, None] * np.column_stack(
        [np.cos(pose[2] + sensor.angles_rad[car]), np.sin(pose[2] + sensor.angles_rad[car])]
    )
    outline = np.vstack([car_outline(c, h) for _, c, h in CLUTTER["cars"][:2]])
    # every hit within 1 mm of one of the two cars' rectangles (axis-aligned: heading 90 deg)
    lo, hi = outline.min(axis=0), outline.max(axis=0)
    assert np.all((pts >= lo - 1e-3) & (pts <= hi + 1e-3))


@pytest.mark.slow
def test_a_drive_through_the_clutter_park_counts_each_class():
    rows = clutter_trial((0,), seed=3)
    clutter = [r for r in rows if r["scene"] == "tree_park_clutter"]
    plain = [r for r in rows if r["scene"] == "tree_park"]
    assert {r["method"] for r in clutter} == {
        "paper",
        "geometric",
        "bailey",
        "paper, short trunks",
        "geometric, short trunks",
        "paper, existence",
        "geometric, existence",
        "bailey, existence",
        "paper, existence, persistent clutter",
        "geometric, existence, persistent clutter",
        "bailey, existence, persistent clutter",
    }
    for r in clutter:
        assert r["objects_trunk"] == 8 and r["objects_post"] == 6 and r["objects_person"] == 6
        assert r["objects_car"] == 3 and r["objects_bush"] == 9
        per_class = sum(r[k] for k in r if k.startswith("landmarks_"))
        assert per_class == r["landmarks"]  # every landmark has one class
        assert r["right"] <= r["landmarks_trunk"] and r["trunks_found"] <= 8
    for r in plain:
        assert r["objects_post"] == 0 and r["landmarks_post"] == 0
        assert r["trunks_found"] >= 6  # the plain park's trees are mapped (Table 3's drive)


def test_map_figures_attribute_landmarks_by_their_beams():
    class Log:  # one landmark from two measurements on beams 10-12 of scans 0 and 1
        meas_track = np.array([5, 5, -1])
        meas_track_unmerged = None
        meas_scan = np.array([0, 1, 1])
        meas_feature = np.array([0, 0, 1])
        landmark_id = np.array([5])
        landmark_xy = np.array([[9.1, 2.5]])

    class Feats:
        circle_beams = np.array([[10, 12], [20, 21]])

    sc = clutter_park()
    labels = np.full((2, 30), -1)
    labels[:, 10:13] = sc.label_of("T1")  # T1 at (9.0, 2.5)
    seq = type("Seq", (), {"scan_labels": labels})()
    f = _map_figures(Log(), sc, seq, [Feats(), Feats()])
    assert (f["landmarks_trunk"], f["right"], f["trunks_found"], f["mapped_trunk"]) == (1, 1, 1, 1)
    Log.landmark_xy = np.array([[9.7, 2.5]])  # 0.7 m off: on the trunk's beams, but wrong
    f = _map_figures(Log(), sc, seq, [Feats(), Feats()])
    assert (f["landmarks_trunk"], f["right"], f["trunks_found"]) == (1, 0, 0)


def test_the_summary_pools_precision_and_recall_over_the_runs():
    def row(run, landmarks, right, found):
        r = {f"{k}_{c}": 0 for k in ("landmarks", "objects", "mapped") for c in CLASSES}
        r |= {"scene": "tree_park_clutter", "method": "paper", "run": run}
        r |= {"landmarks": landmarks, "right": right, "trunks": 8, "trunks_found": found}
        r |= {"landmarks_trunk": right, "landmarks_post": landmarks - right}
        r |= {"objects_post": 6, "mapped_post": landmarks - right}
        return r

    (s,) = summary_records([row(0, 10, 8, 8), row(1, 8, 7, 6)])
    assert s["precision"] == 15 / 18 and s["recall"] == 14 / 16 and s["landmarks_mean"] == 9
    assert s["landmarks_post_mean"] == 1.5 and s["mapped_post"] == 3 / 12
    assert math.isnan(s["mapped_car"])  # no car in these rows
    assert "mapped_none" not in s


def test_the_table_is_written_from_the_runs(tmp_path):
    from experiments.paper.sim_clutter import TABLE

    rows = [
        {f"{k}_{c}": 0 for k in ("landmarks", "objects", "mapped") for c in CLASSES}
        | {"scene": scene, "method": "paper", "run": 0, "landmarks": 9, "right": 8}
        | {"trunks": 8, "trunks_found": 8, "landmarks_trunk": 8, "landmarks_bush": 1}
        for scene in ("tree_park", "tree_park_clutter")
    ]
    md, csv_path = TABLE.write(tmp_path, rows)
    text = md.read_text()
    assert "on bushes, mean" in text and "nothing labelled held" not in text
    assert csv_path.read_text().count("\n") == 3  # a header and one row per scene
