"""`slam.visual.show_scan`: the visualiser is fed from the scan's record (`slam.loop.ScanResult`)
and the filter, never from the loop's internals."""

from __future__ import annotations

import math

import numpy as np

from slam import run_slam
from slam.closure import ClosureDecision, ClosureEvent
from slam.ekf import Filter, initial_state
from slam.loop import ScanResult
from slam.sources import Measurements
from slam.visual import NullVisualiser, show_scan

from .test_run import LANDMARKS, drive_sequence, point_features

LASER = np.zeros(3)


class Calls(NullVisualiser):
    """Every call, by method name: [args]."""

    def __init__(self) -> None:
        self.calls: dict[str, list] = {}

    def __getattribute__(self, name):
        if name.startswith("log_") or name == "set_scan":
            return lambda *a, **k: self.calls.setdefault(name, []).append(a)
        return super().__getattribute__(name)


def _result(status, closure=None) -> tuple[Filter, ScanResult]:
    f = Filter(initial_state(np.zeros(3), np.eye(3) * 1e-4))
    f.add_landmark(np.array([10.0, 0.0]), np.eye(2) * 1e-4, LASER, 7)
    z = np.array([[10.0, 0.0], [5.0, 0.5]])
    meas = Measurements(
        k=3, scan=None, features=None, z=z, R=np.tile(np.eye(2), (2, 1, 1)), status=status
    )
    res = ScanResult(
        meas=meas,
        status=np.array([7, -1]),
        track=np.array([7, 4]),
        nis=1.0,
        n_used=1,
        n_pending=1,
        tentative_xy=np.array([[4.4, 2.4]]),
        closure=closure,
    )
    return f, res


def _event(outcome: str) -> ClosureEvent:
    return ClosureEvent(3, 0.6, 8, 9, 7, 2, 1.0, 2.0, outcome)


def test_the_scan_is_shown_from_its_record():
    """The association drawn is the record's (measurement 0 to landmark 7), whatever the
    measurements' own status says; the tentatives are the record's; an accepted match and
    the sweep's merges are marked, a match with too few landmarks is not."""
    seq = drive_sequence(1.5, 0.0, n_scans=5)
    f, res = _result(np.array([-1, -1]))
    res = ScanResult(
        **{**res.__dict__, "closure": ClosureDecision(_event("accepted"), ((7, 9, 3), (2, 5, 3)))}
    )
    vis = Calls()
    show_scan(vis, seq, LASER, f, res)
    frm, to = vis.calls["log_associations"][0]
    np.testing.assert_allclose(frm, [[10.0, 0.0]], atol=1e-12)
    np.testing.assert_allclose(to, [[10.0, 0.0]], atol=1e-12)
    np.testing.assert_array_equal(vis.calls["log_tentatives"][0][0], [[4.4, 2.4]])
    assert vis.calls["log_closure"][0][0]["outcome"] == "accepted"
    assert vis.calls["log_duplicates"][0][0] == [(7, 9), (2, 5)]
    assert vis.calls["set_scan"][0] == (3, float(seq.scan_t[3]))
    # a record without the scan (a detections source reads none): the sequence's scan 3
    scan = vis.calls["log_scan"][0][0]
    assert np.array_equal(scan.raw_ranges_m, seq.scan(3).raw_ranges_m, equal_nan=True)
    assert vis.calls["log_features"][0][0] is scan
    f, res = _result(np.array([-1, -1]), ClosureDecision(_event("too few")))
    vis = Calls()
    show_scan(vis, seq, LASER, f, res)
    assert "log_closure" not in vis.calls and "log_duplicates" not in vis.calls


def test_a_sequence_of_detections_alone_logs_no_scan():
    """No raw ranges and no scan in the record (a detections source): no scan to draw, so no
    `log_scan` (it was an all-NaN scan built at every scan); the features go without one, the
    laser's pose with them."""
    import dataclasses

    seq = drive_sequence(1.5, 0.0, n_scans=5)
    one = np.array([0, 2], np.int64)  # a detection in scans 0 and 2; the ranges dropped
    seq = dataclasses.replace(
        seq,
        scan_ranges=None,
        det_scan=one,
        det_range=np.array([10.0, 9.0]),
        det_bearing=np.zeros(2),
        det_radius=np.full(2, 0.2),
    )
    f, res = _result(np.array([-1, -1]))
    vis = Calls()
    show_scan(vis, seq, LASER, f, res)
    assert "log_scan" not in vis.calls
    ((scan, features, pose),) = vis.calls["log_features"]
    assert scan is None and features is None
    np.testing.assert_array_equal(pose, f.pose)  # LASER is the identity


def test_a_run_shows_every_scan_once_with_its_used_measurements():
    """A whole run through a visualiser: one set_scan per scan in order, and the lines drawn
    per scan are the measurements the log says updated a landmark."""
    seq = drive_sequence(1.5, 0.0, n_scans=30)
    feats = point_features(seq, LANDMARKS, np.random.default_rng(0))
    vis = Calls()
    lg = run_slam(seq, features=feats, visualiser=vis)
    assert [c[0] for c in vis.calls["set_scan"]] == list(range(seq.n_scans))
    drawn = [c[0].shape[0] for c in vis.calls["log_associations"]]
    used = np.bincount(lg.meas_scan[lg.meas_status >= 0], minlength=seq.n_scans)
    assert drawn == used.tolist() and sum(drawn) > 0
    assert not math.isnan(float(np.nanmax(lg.scan_nis)))
