"""Map policy "existence" in the run loop (`slam.existence_map`), on a drive through the
simulated park with clutter (`experiments.sim.clutter`): what the log says of each landmark's
existence and of the landmarks that left, and that the default policy ignores its settings."""

import numpy as np
import pytest

from experiments.paper.sim_clutter import _map_figures
from experiments.paper.slam import Exp2Config, run_config
from experiments.sim.clutter import clutter_park
from experiments.sim.trajectory import MONTE_CARLO_PATH, CycabParams, simulate_cycab_run
from features import extract_features
from slam import run_slam


def clutter_drive():
    """(scene, sequence, experiment 2's geometric config, its features) of one Cycab drive
    through the clutter park (seed 3)."""
    scene = clutter_park()
    seq = simulate_cycab_run(np.random.default_rng(3), scene, CycabParams(**MONTE_CARLO_PATH))
    cfg = run_config(Exp2Config(), "geometric")
    kw = cfg.features.extractor_kwargs()
    feats = [extract_features(seq.scan(k), "geometric", **kw) for k in range(seq.n_scans)]
    return scene, seq, cfg, feats


@pytest.fixture(scope="module")
def drive():
    return clutter_drive()


@pytest.mark.parametrize("method", ["ihgr", "ihgr-window"])
def test_every_landmark_carries_its_existence_and_those_that_left_say_why(drive, method):
    scene, seq, cfg, feats = drive
    c = cfg.with_(**{"map_policy.policy": "existence", "association.method": method})
    lg = run_slam(seq, c, features=feats)
    pol = c.map_policy
    assert lg.landmark_existence.shape == lg.landmark_id.shape
    assert np.all(lg.landmark_existence >= pol.existence_remove_prob)
    assert lg.departures, "a landmark whose existence fell must have left the map"
    for lid, k, why, r in lg.departures:
        assert why == "existence" and r < pol.existence_remove_prob
        assert lid not in lg.landmark_id.tolist() and 0 <= k < seq.n_scans
        # it left after its last update: none of its measurements was used after that scan
        used = lg.obs_scan[lg.obs_landmark == lid]
        assert used.size == 0 or used.max() <= k
    f = _map_figures(lg, scene, seq, feats)
    assert f["trunks_found"] == f["trunks"]  # the trunks stay


def test_the_confirm_policy_ignores_the_existence_settings(drive):
    _, seq, cfg, feats = drive
    a = run_slam(seq, cfg, features=feats)
    b = run_slam(seq, cfg.with_(**{"map_policy.existence_pd_max": 0.3}), features=feats)
    np.testing.assert_array_equal(a.landmark_xy, b.landmark_xy)
    np.testing.assert_array_equal(a.pose, b.pose)
    assert a.landmark_existence is None and a.departures == []


def test_the_visualiser_and_the_run_log_show_each_landmarks_existence_and_departures(
    drive, tmp_path
):
    from experiments.io.run_log import DEPARTURE_REASONS, read_existence, write_run_log
    from slam.visual import NullVisualiser

    _, seq, cfg, feats = drive

    class Seen(NullVisualiser):
        def __init__(self):
            self.existence, self.departures = [], []

        def log_landmarks(self, xy, cov, ids, existence=None):
            assert existence is not None and len(existence) == len(ids)
            self.existence.append(np.asarray(existence))

        def log_departures(self, departures):
            self.departures += departures

    vis = Seen()
    c = cfg.with_(**{"map_policy.policy": "existence"})
    lg = run_slam(seq, c, features=feats, visualiser=vis)
    np.testing.assert_array_equal(vis.existence[-1], lg.landmark_existence)
    assert [(lid, why) for lid, why, _ in vis.departures] == [
        (lid, why) for lid, _, why, _ in lg.departures
    ]
    np.testing.assert_array_equal([r for *_, r in vis.departures], [d[3] for d in lg.departures])
    write_run_log(tmp_path / "run_log.npz", lg)
    got = read_existence(tmp_path)
    np.testing.assert_array_equal(got["landmark_existence"], lg.landmark_existence)
    np.testing.assert_array_equal(got["landmark_id"], lg.landmark_id)
    assert got["departed_landmark"].tolist() == [d[0] for d in lg.departures]
    assert got["departed_scan"].tolist() == [d[1] for d in lg.departures]
    assert [DEPARTURE_REASONS[i] for i in got["departed_reason"]] == [d[2] for d in lg.departures]
    # a run of the paper's policy writes none of them
    write_run_log(tmp_path / "plain.npz", run_slam(seq, cfg, features=feats))
    assert read_existence(tmp_path / "plain.npz") == {}


def test_the_existence_settings_derived_from_a_run_recover_what_the_extractor_needs(drive):
    """`derive_existence` on the paper's policy run of the drive, no truth used: the fewest
    free beams it detects a trunk with is the extractor's min_circle_points (a circle needs
    that many beams; geometric without short trunks), the trunks it keeps seeing are detected
    in nearly every scan they are well in view, and birth_prob is the share of the started
    tentatives that became the map's landmarks."""
    from experiments.eval.existence_rates import WELL_SEEN, derive_existence

    _, seq, cfg, feats = drive
    lg = run_slam(seq, cfg, features=feats)
    d = derive_existence(lg, seq, (0, seq.n_scans))
    s = d["settings"]
    assert s["map_policy.existence_min_beams"] == cfg.features.extractor.min_circle_points
    e, det = np.array(d["expected_by_free_beams"]), np.array(d["detected_by_free_beams"])
    assert det[: s["map_policy.existence_min_beams"] - 1].sum() <= 0.1 * e[:3].sum()
    assert s["map_policy.existence_pd_max"] > 0.9
    assert det[WELL_SEEN:].sum() / e[WELL_SEEN:].sum() > 0.9
    assert d["tracks_joined"] == lg.landmark_id.size  # nothing left the map in this run
    assert s["map_policy.existence_birth_prob"] == d["tracks_joined"] / d["tracks_started"]
    assert 0 < s["map_policy.existence_false_per_scan"] < 5


def test_the_existence_table_has_a_row_per_extractor_and_protocol(tmp_path):
    from experiments.paper.victoria_park.existence_policy import TABLE, existence_rows

    row = {
        "precision": 0.9, "recall": 0.95, "f1": 0.92, "landmarks": 80, "removed": 3,
        "existence_pd_max": 0.8, "existence_min_beams": 2, "existence_false_per_scan": 1.5,
        "existence_birth_prob": 0.3,
    }  # fmt: skip
    results = [
        {
            "extractor": ex,
            "rows": [
                row | {"extractor": ex, "derived_on": f"scans {a}", "judged_on": f"scans {b}"}
                for a, b in (
                    ("1-1000", "1001-2000"),
                    ("1001-2000", "1-1000"),
                    ("1-2000", "1-2000 (in-sample)"),
                )
            ],
        }  # fmt: skip
        for ex in ("bailey", "geometric")
    ]
    md, csv_path = TABLE.write(tmp_path, existence_rows(results))
    assert csv_path.read_text().count("\n") == 1 + 3 * 2
    assert "scans 1-2000 (in-sample)" in md.read_text() and "removed by existence" in md.read_text()


def test_a_run_with_no_well_seen_landmark_derives_nothing_and_says_why(drive):
    from experiments.errors import DataError
    from experiments.eval.existence_rates import derive_existence

    _, seq, cfg, feats = drive
    lg = run_slam(seq, cfg, features=feats)
    with pytest.raises(DataError, match="no landmark of the run seen in more than 10000 scans"):
        derive_existence(lg, seq, (0, seq.n_scans), established=10000)


def test_a_run_without_a_false_circle_gives_half_a_circle_over_its_scans(drive):
    """The clutter density must be above 0: a run whose every considered circle became a
    landmark derives half a circle over the scans it used."""
    import dataclasses

    from experiments.eval.existence_rates import derive_existence
    from slam.log import AMBIGUOUS

    _, seq, cfg, feats = drive
    lg = run_slam(seq, cfg, features=feats)
    explained = np.isin(lg.meas_track, lg.landmark_id) & (lg.meas_track >= 0)
    clean = dataclasses.replace(lg, meas_status=np.where(explained, lg.meas_status, AMBIGUOUS))
    d = derive_existence(clean, seq, (0, seq.n_scans))
    assert d["settings"]["map_policy.existence_false_per_scan"] == 0.5 / d["scans_used"]


@pytest.mark.data
def test_existence_reads_the_beams_with_published_detections_too(vp_dir):
    """A detections source needs no raw scan for its circles, but existence needs the beams:
    with them, the published detections give the same existence as our `bailey` extractor on
    the same raw scans (the reimplementation reproduces the detections on these scans)."""
    from experiments.io.config_file import load_slam_config, preset_path
    from experiments.io.victoria_park import load_victoria_park

    seq = load_victoria_park(vp_dir, n_scans=300)
    cfg = load_slam_config(preset_path("victoria_park_ute")).with_(
        **{"map_policy.policy": "existence"}
    )
    logs = {m: run_slam(seq, cfg.with_(**{"features.method": m})) for m in ("detections", "bailey")}
    a, b = logs["detections"], logs["bailey"]
    assert a.landmark_id.size > 10
    np.testing.assert_array_equal(a.landmark_id, b.landmark_id)
    np.testing.assert_allclose(a.landmark_existence, b.landmark_existence, rtol=1e-9, atol=0)
