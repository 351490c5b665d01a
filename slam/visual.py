"""What a run shows as it goes: the visualiser interface (`NullVisualiser`, which does
nothing, as kiss-icp's StubVisualizer) and the one function that feeds it a scan."""

from __future__ import annotations

import numpy as np

from slam import se2

__all__ = ["NullVisualiser", "show_scan"]


class NullVisualiser:
    """The visualiser interface; does nothing (kiss-icp's StubVisualizer).

    Poses are world [x, y, theta]; `pose` of log_scan/log_features is the laser's world pose.
    """

    def set_scan(self, k: int, stamp_s: float | None = None) -> None: ...
    def log_scan(self, scan, pose=None, path: str = "world/scan") -> None: ...
    def log_features(self, scan, features, pose=None, path: str = "world/features") -> None: ...
    def log_vehicle(self, pose, cov) -> None: ...
    def log_landmarks(self, xy, cov, ids, existence=None) -> None: ...
    def log_departures(self, departures: list) -> None: ...
    def log_tentatives(self, xy) -> None: ...
    def log_associations(self, from_xy, to_xy) -> None: ...
    def log_truth(self, pose) -> None: ...
    def log_closure(self, event: dict) -> None: ...
    def log_duplicates(self, pairs: list) -> None: ...


def show_scan(vis, seq, laser: np.ndarray, state, result) -> None:
    """One scan of a run of the sequence `seq`: what its steps produced (`result`, the loop's
    `slam.loop.ScanResult`) and the filter `state` after it; laser: T_vehicle_laser."""
    meas, k = result.meas, result.meas.k
    vis.set_scan(k, float(seq.scan_t[k]))
    T_world_vehicle = state.pose
    T_world_laser = se2.compose(T_world_vehicle, laser)
    scan = meas.scan  # a detections source reads none: the sequence's, when it has ranges
    if scan is None and seq.scan_ranges is not None:
        scan = seq.scan(k)
    if scan is not None:  # (a sequence of detections alone has no return to draw)
        vis.log_scan(scan, T_world_laser)
    vis.log_features(scan, meas.features, T_world_laser)  # its segments need the scan
    vis.log_vehicle(T_world_vehicle, state.pose_cov)
    if result.existence is None:
        vis.log_landmarks(state.landmarks_xy, state.landmark_covs, state.landmark_ids)
    else:  # map policy "existence": each landmark's, and those that left
        ids = state.landmark_ids
        vis.log_landmarks(state.landmarks_xy, state.landmark_covs, ids, existence=result.existence)
        removed = result.decisions.removed if result.decisions is not None else []
        if removed:
            r = result.departed_existence
            vis.log_departures([(lid, why, v) for (lid, why), v in zip(removed, r)])
    vis.log_tentatives(result.tentative_xy)
    # (a landmark a loop closure merged away in this scan is no longer in the state)
    status = np.asarray(result.status)
    used = np.flatnonzero(status >= 0)
    at = state.positions_of(status[used])  # (one sort a scan, not a search a measurement)
    used, at = used[at >= 0], at[at >= 0]
    if used.size:
        ang = T_world_laser[2] + meas.z[used, 1]
        frm = T_world_laser[:2] + meas.z[used, 0:1] * np.stack([np.cos(ang), np.sin(ang)], 1)
        vis.log_associations(frm, state.landmarks_xy[at])
    else:
        vis.log_associations(np.zeros((0, 2)), np.zeros((0, 2)))
    if seq.truth_t is not None:
        vis.log_truth(se2.interpolate_poses(seq.scan_t[k], seq.truth_t, seq.truth_pose)[0])
    closure = result.closure
    if closure is not None and closure.event is not None:
        if closure.event.outcome != "too few":  # a match worth a mark on the timeline
            vis.log_closure(closure.event.to_dict())
    if closure is not None and closure.duplicates:
        vis.log_duplicates([(a, b) for a, b, _ in closure.duplicates])
