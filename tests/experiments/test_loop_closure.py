"""Loop closure on simulated loops with known truth (`experiments.paper.loop_closure`)."""

from __future__ import annotations

import functools

import numpy as np
import pytest
from scipy.stats import chi2
from support import read_recording

from experiments.paper.loop_closure import _identities, drive_features, loop_config
from experiments.sim.loops import loop_scene
from slam import interpolate_poses, run_slam


@functools.cache  # a drive and its features, made once a module (several tests read them)
def _drive_features(seed: int, kind: str) -> tuple:
    return drive_features(seed, kind)


@functools.cache  # deterministic, and the tests only read the run: one run per drive and setting
def _run(seed: int, kind: str, closure: bool):
    seq, feats = _drive_features(seed, kind)
    return seq, feats, run_slam(seq, loop_config(closure), features=feats)


@pytest.mark.slow
def test_a_closed_loop_recovers_the_map_of_the_stand():
    """Park drive 5: without closure the return maps the stand a second time (35 trees
    twice); with it, one closure merges the duplicates onto their own trees, no tree is
    mapped twice, and every landmark lies within its 99.9% ellipse of its tree."""
    seq, feats, off = _run(5, "park", False)
    ident_off = _identities(off, seq, feats)
    final_off = [ident_off[int(i)] for i in off.landmark_id if int(i) in ident_off]
    assert len(final_off) - len(set(final_off)) >= 20
    seq, feats, on = _run(5, "park", True)
    accepted = [e for e in on.closures if e["outcome"] == "accepted"]
    assert accepted and all(e["best"] >= 6 and e["best"] - e["second"] >= 3 for e in accepted)
    ident = _identities(on, seq, feats)
    assert all(ident[a] == ident[b] for e in accepted for a, b in e["merged"])
    final = [ident[int(i)] for i in on.landmark_id]
    assert len(final) == len(set(final))  # no tree twice
    trees = seq.truth_landmarks[np.array(final), :2]
    d = on.landmark_xy - trees
    m2 = np.einsum("ni,nij,nj->n", d, np.linalg.inv(on.landmark_cov), d)
    assert np.all(m2 <= chi2.ppf(0.999, 2))


@pytest.mark.slow
def test_a_return_the_filter_is_too_sure_of_is_closed_by_re_registration():
    """Park drive 2 comes back 3.2 m off with a covariance that refuses the true match (joint
    NIS above its bound): dead reckoning allows the drift and one rigid motion fits the pairs,
    so the local map is re-registered; each pair is one tree, no tree is mapped twice, and the
    final error is a fraction of the drift at the return."""
    seq, feats, off = _run(2, "park", False)
    truth = interpolate_poses(seq.scan_t, seq.truth_t, seq.truth_pose)
    seq, feats, on = _run(2, "park", True)
    accepted = [e for e in on.closures if e["outcome"] == "accepted"]
    assert [e["re_registered"] for e in accepted] == [True]
    e = accepted[0]
    assert e["nis"] > e["nis_bound"] and e["drift_nis"] <= e["drift_bound"]
    assert e["shape_nis"] <= e["shape_bound"]
    ident = _identities(on, seq, feats)
    assert all(ident[a] == ident[b] for a, b in e["merged"])
    final = [ident[int(i)] for i in on.landmark_id]
    assert len(final) == len(set(final))
    err_on = np.hypot(*(on.pose[-1, :2] - truth[-1, :2]))
    err_off = np.hypot(*(off.pose[-1, :2] - truth[-1, :2]))
    assert err_off > 2.0 and err_on < 0.25 * err_off


@pytest.mark.slow
def test_after_a_re_registration_the_nearby_duplicates_are_swept_without_an_update():
    """Park drive 6: the match pairs 6 trees and re-registers the local map; the 4 other trees
    of the return mapped twice, within the laser's range, are swept up by marginalising the
    duplicates (their measurements relabelled to the old landmarks): every pair is one tree
    and no tree is mapped twice. The sweep's duplicates are removed, not merged by an update,
    so the old landmarks end where the match's merge left them."""
    seq, feats, on = _run(6, "park", True)
    accepted = [e for e in on.closures if e["outcome"] == "accepted"]
    assert len(accepted) == 1 and accepted[0]["re_registered"]
    e = accepted[0]
    assert len(e["merged"]) > e["best"]  # the match's pairs, then the sweep's
    ident = _identities(on, seq, feats)
    assert all(ident[a] == ident[b] for a, b in e["merged"])
    final = [ident[int(i)] for i in on.landmark_id]
    assert len(final) == len(set(final))


def test_the_local_sweep_marginalises_without_moving_the_map():
    """`LoopCloser.merge(update=False)` (the sweep after a re-registration) removes the
    duplicates from the state and relabels them in the history, and leaves every other estimate
    and covariance entry as it was; the update merge moves the kept landmark."""
    from slam.closure import LoopCloser
    from slam.config import ClosureConfig
    from slam.ekf import Filter, initial_state
    from slam.history import RunHistory

    def state():
        f = Filter(initial_state(np.zeros(3), np.diag([0.1, 0.1, 0.01])))
        for lid, z in ((1, (10.0, 0.1)), (2, (10.3, 0.12)), (3, (20.0, -0.5))):
            f.add_landmark(np.array(z), np.diag([0.04, 1e-4]), np.zeros(3), lid)
        return f

    history = RunHistory(np.zeros(1))
    closer = LoopCloser(ClosureConfig(enabled=True), None, np.zeros(3), history, gate_prob=0.99)
    f = state()
    before = f.snapshot()
    assert closer.merge(f, np.array([1]), np.array([2]), 0.0, update=False) == [(1, 2)]
    assert history.alias == {2: 1} and f.landmark_ids.tolist() == [1, 3]
    keep = np.r_[0:5, 7:9]  # the pose, landmarks 1 and 3
    assert np.array_equal(f.x, before.x[keep])
    assert np.array_equal(f.P, before.P[np.ix_(keep, keep)])
    g = state()
    closer.merge(g, np.array([1]), np.array([2]), 0.0)
    assert not np.allclose(g.x[3:5], before.x[3:5])


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(4))
def test_a_look_alike_orchard_gives_no_false_closure(seed):
    """Rows of identical trees one spacing apart: whatever the closure accepts pairs each
    landmark with its own tree (the experiment runs 100 drives)."""
    assert loop_scene("orchard", 0).truth_landmarks.shape[0] == 60
    seq, feats, on = _run(seed, "orchard", True)
    ident = _identities(on, seq, feats)
    for e in on.closures:
        if e["outcome"] == "accepted":
            assert all(ident.get(a) == ident.get(b) for a, b in e["merged"])


@pytest.mark.slow
def test_the_experiment_writes_its_table(tmp_path):
    """`trunkslam reproduce loop-closure --quick`: two drives of each kind, a row per scene,
    filter and closure setting, the run count in the manifest, the figure, and the recording
    of the figure's run with closure, its closure marked on the timeline."""
    import csv
    import json

    from typer.testing import CliRunner

    from experiments.cli import app

    out = tmp_path / "r"
    args = ["reproduce", "loop-closure", "--quick", "--workers", "1", "--out", str(out)]
    res = CliRunner().invoke(app, args)  # one worker: no pool of processes to start
    assert res.exit_code == 0, res.output
    rows = list(csv.DictReader((out / "loop_closure.csv").open()))
    assert [(r["scene"], r["jacobians"], r["closure"]) for r in rows] == [
        (scene, jac, closure)
        for scene in ("park", "orchard")
        for jac in ("standard", "first estimates")
        for closure in ("off", "on")
    ]
    assert all(r["runs"] == "2" for r in rows)
    assert all(int(r["false_closures"]) == 0 for r in rows)
    assert json.loads((out / "manifest.json").read_text())["config"]["loop-closure"]["runs"] == 4
    assert (out / "loop_closure_map.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    rec = read_recording(out / "loop_closure.rrd")  # the figure's run with closure
    assert {"events/closures", "world/landmarks", "world/truth/trees"} <= set(rec["entities"])


@pytest.mark.slow
def test_the_smoother_sees_the_closed_loop():
    """The run log of the closed park drive 5 relabels the merged landmarks' measurements, so
    the smoother's graph has one landmark per tree of the final map, with the sightings of
    both passes: it ends on the truth, as close as the filter."""
    from slam import interpolate_poses
    from slam.smoother import problem_from_log, smooth

    seq, feats, on = _run(5, "park", True)
    p = problem_from_log(on)
    assert set(p.meas_landmark.tolist()) == set(on.landmark_id.tolist())
    merged = {b for e in on.closures if e["outcome"] == "accepted" for _, b in e["merged"]}
    assert merged and not merged & set(p.meas_landmark.tolist())
    first = {int(i): int(s) for i, s in zip(on.landmark_id, on.landmark_first_scan)}
    late = [lid for lid, s in zip(p.meas_landmark, p.meas_scan) if s > 900]
    assert any(first[lid] < 300 for lid in late)  # old trees seen again on the way back
    res = smooth(p)
    truth = interpolate_poses(seq.scan_t, seq.truth_t, seq.truth_pose)
    err = np.hypot(*(res.pose[-1, :2] - truth[-1, :2]))
    assert err < max(0.5, 1.5 * np.hypot(*(on.pose[-1, :2] - truth[-1, :2])))


@pytest.mark.slow
def test_the_run_shows_its_closures():
    """A visualiser of the run gets each match worth marking (`log_closure`) at its scan,
    here the accepted closure of park drive 5, and each duplicate sweep's merges
    (`log_duplicates`) at theirs."""
    from slam.visual import NullVisualiser

    class Marks(NullVisualiser):
        def __init__(self):
            self.scan, self.marks = -1, []

        def set_scan(self, k, stamp_s=None):
            self.scan = k

        def log_closure(self, event):
            self.marks.append((self.scan, event))

        def log_duplicates(self, pairs):
            self.marks.append((self.scan, {"scan": self.scan, "outcome": "swept", "pairs": pairs}))

    seq, feats = _drive_features(5, "park")
    vis = Marks()
    lg = run_slam(seq, loop_config(True), features=feats, visualiser=vis)
    shown = [e for e in lg.closures if e["outcome"] != "too few"]
    assert [(s, e["scan"]) for s, e in vis.marks] == [(e["scan"], e["scan"]) for e in shown]
    assert any(e["outcome"] == "accepted" for _, e in vis.marks)
    # drive 1: the duplicate sweep marginalises one landmark out, marked at its scan
    seq, feats = drive_features(1, "park")
    vis = Marks()
    lg = run_slam(seq, loop_config(True), features=feats, visualiser=vis)
    assert len(lg.closure_duplicates) == 1
    keep, drop, scan = lg.closure_duplicates[0]
    swept = [(s, e["pairs"]) for s, e in vis.marks if e["outcome"] == "swept"]
    assert swept == [(scan, [(keep, drop)])]
