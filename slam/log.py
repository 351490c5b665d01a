"""What a run did (`SlamLog`), and the one small builder `slam.run` fills scan by scan."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = [
    "AMBIGUOUS",
    "CONFIRMED",
    "NEW_TENTATIVE",
    "OUT_OF_RANGE",
    "SKIPPED",
    "TENTATIVE_HIT",
    "TIMING_KEYS",
    "LogBuilder",
    "SlamLog",
]

TIMING_KEYS = ("predict", "features", "associate", "update", "manage", "total")

# Status of each measurement in SlamLog.meas_status (>= 0: the landmark id it updated).
NEW_TENTATIVE = -1
TENTATIVE_HIT = -2
CONFIRMED = -3
AMBIGUOUS = -4
OUT_OF_RANGE = -5
SKIPPED = -6


@dataclass(frozen=True, eq=False)
class SlamLog:
    """Everything one run did. N scans; world frame; m, rad, s.

    scan_t: (N,) scan times: the times the scans were measured, the poses' times (their stamps
        minus `vehicle.laser_latency_s`; the stamps themselves when it is 0).
    pose, pose_cov: (N, 3), (N, 3, 3) the estimate of the rear-axle centre after the scan's
        update. pred_pose, pred_pose_cov: the same after the prediction, before the update
        (pred == pose for scans without an update).
    landmark_xy (n, 2), landmark_cov (n, 2, 2), landmark_id (n,), landmark_first_scan (n,),
        landmark_n_obs (n,): the final map (first_scan: the scan it joined the map; n_obs: the
        scans it was associated in, its tentative sightings included).
    obs_*: one row per measurement used in an update: obs_scan, obs_feature (circle index in the
        scan's features), obs_landmark (id), obs_z (range, bearing), obs_innov (z - z_hat),
        obs_innov_cov (2, 2) its block of the joint innovation covariance.
    meas_*: one row per circle extracted: meas_scan, meas_feature, meas_z (K, 2), meas_R
        (K, 2, 2), meas_status (landmark id >= 0 when used in an update; -1 new tentative,
        -2 tentative seen again, -3 tentative confirmed into the map, -4 ambiguous (gated but not
        assigned, ignored), -5 beyond max_feature_range_m, -6 in a scan skipped: the vehicle
        had not moved `SlamConfig.min_travel_m` since the last scan used), meas_radius_m (K,)
        the circle's radius (NaN when the features have none).
    scan_nis (N,), scan_nis_dof (N,): NIS of each scan's batch update and its degrees of
        freedom (NaN, 0 without an update); scan_logdet (N,): ln |S| of that batch (NaN without).
    scan_skipped (N,) bool: the scan was predicted only (`SlamConfig.min_travel_m`).
    n_features, n_associated, n_tentative, n_map: (N,) per scan.
    timing_s: {"predict", "features", "associate", "update", "manage", "total"} -> (N,) s.
    meas_track (K,): the landmark or tentative id each measurement was paired with or started
        (the id a tentative keeps if it joins the map), -1 for ambiguous and out-of-range ones.
    start_pose (3,), start_cov (3, 3): the filter's prior at the first scan (world frame).
    laser_pose (3,): the laser's pose in the vehicle frame that the run used (T_vehicle_laser).
    antenna_pose (3,): the GPS antenna's in the vehicle frame (T_vehicle_antenna): the run's
        configuration, else the sequence's, else the laser's (`slam.start.antenna_of`).
    odo_delta (N, 3), odo_cov (N, 3, 3): row k (k >= 1) is the odometry increment from scan
        k - 1 to scan k in the frame of the pose at k - 1 (x forward, y left, theta), and its
        covariance in that frame (the prediction's Q rotated into it, floor noise included);
        row 0 is zeros. The EKF's prediction is pose[k - 1] composed with odo_delta[k].
    final_x, final_P: the final state. landmark ids index `final_x` via landmark_id order.
    start: "truth", "gps", "origin" or "given" (`run_slam`'s prior).
    features_method, association_method: names used.
    config: the resolved configuration (plain types).
    window_stats: association "ihgr-window" only: K, steps, fractional first LPs, steps the
        rounding changed (more than one LP solve), LP solves, track hypotheses built.
    closures: with `[closure] enabled`, every constellation match tried
        (`slam.closure.ClosureEvent.to_dict()`), accepted or not; a merged landmark's
        measurements carry the id of the landmark it was merged into; meas_track_unmerged
        then holds the tracks as they were before any merge (None when nothing was merged).
    closure_duplicates: with `[closure] enabled`, the landmarks the duplicate sweep
        marginalised out, [kept id, dropped id, scan] each (`slam.closure`, step 5).
    landmark_existence (n,): map policy "existence" only, the existence of each landmark of
        the final map (`slam.existence_map`; None otherwise).
    departures: the landmarks that left the map other than by a closure merge, [landmark id,
        scan, reason, existence] each: reason "existence" (its existence fell below
        map_policy.existence_remove_prob, the figure logged) or "pruned" (the map policy's
        pruner; existence NaN). Merged landmarks are in `closures` / `closure_duplicates`.
    joint_dropped: with `[association] joint_check`, every pairing the joint test dropped
        (`slam.joint_gate`), [scan, measurement, landmark id] each; the measurement's status
        is then AMBIGUOUS (None without the check).
    """

    scan_t: np.ndarray
    pose: np.ndarray
    pose_cov: np.ndarray
    pred_pose: np.ndarray
    pred_pose_cov: np.ndarray
    landmark_xy: np.ndarray
    landmark_cov: np.ndarray
    landmark_id: np.ndarray
    landmark_first_scan: np.ndarray
    landmark_n_obs: np.ndarray
    obs_scan: np.ndarray
    obs_feature: np.ndarray
    obs_landmark: np.ndarray
    obs_z: np.ndarray
    obs_innov: np.ndarray
    obs_innov_cov: np.ndarray
    meas_scan: np.ndarray
    meas_feature: np.ndarray
    meas_z: np.ndarray
    meas_R: np.ndarray
    meas_status: np.ndarray
    meas_track: np.ndarray
    meas_radius_m: np.ndarray
    scan_nis: np.ndarray
    scan_nis_dof: np.ndarray
    scan_logdet: np.ndarray
    scan_skipped: np.ndarray
    n_features: np.ndarray
    n_associated: np.ndarray
    n_tentative: np.ndarray
    n_map: np.ndarray
    timing_s: dict
    start_pose: np.ndarray
    start_cov: np.ndarray
    laser_pose: np.ndarray
    odo_delta: np.ndarray
    odo_cov: np.ndarray
    final_x: np.ndarray
    final_P: np.ndarray
    start: str
    features_method: str
    association_method: str
    config: dict
    window_stats: dict | None = None
    closures: list | None = None
    closure_duplicates: list | None = None
    meas_track_unmerged: np.ndarray | None = None
    antenna_pose: np.ndarray | None = None
    landmark_existence: np.ndarray | None = None
    departures: list | None = None
    joint_dropped: list | None = None

    @property
    def n_scans(self) -> int:
        return int(self.scan_t.shape[0])


class LogBuilder:
    """Collects a run's per-scan figures and measurement rows; `build` makes the `SlamLog`
    with what the run's `slam.history.RunHistory` holds (predictions, odometry, landmarks'
    first scans, sightings and merges)."""

    def __init__(self, scan_t: np.ndarray) -> None:
        n = scan_t.shape[0]
        self.scan_t = scan_t
        self.pose = np.empty((n, 3))
        self.pose_cov = np.empty((n, 3, 3))
        self.nis = np.full(n, np.nan)
        self.nis_dof = np.zeros(n, np.int64)
        self.logdet = np.full(n, np.nan)
        self.skipped = np.zeros(n, bool)
        self.counts = {
            k: np.zeros(n, np.int64) for k in ("n_features", "n_associated", "n_tentative", "n_map")
        }
        self.timing = {k: np.zeros(n) for k in TIMING_KEYS}
        # one array per scan (a block of rows), joined by `build`
        self.obs: dict[str, list] = {
            k: [] for k in ("scan", "feature", "landmark", "z", "innov", "S")
        }
        self.meas: dict[str, list] = {
            k: [] for k in ("scan", "feature", "z", "R", "status", "track", "radius")
        }
        self._block_of: dict[int, int] = {}  # scan -> its block in self.meas
        self.start_pose = np.zeros(3)
        self.start_cov = np.zeros((3, 3))
        self.laser_pose = np.zeros(3)
        self.antenna_pose = np.zeros(3)
        self.departures: list = []

    def departed(self, k: int, lid: int, reason: str, existence: float) -> None:
        """Landmark lid left the map after scan k, for `reason` (`SlamLog.departures`)."""
        self.departures.append([int(lid), int(k), str(reason), float(existence)])

    def started(self, pose: np.ndarray, cov: np.ndarray, laser_pose, antenna_pose) -> None:
        """The filter's prior at the first scan, the laser and antenna poses used."""
        self.start_pose = np.array(pose, dtype=np.float64)
        self.start_cov = np.array(cov, dtype=np.float64)
        self.laser_pose = np.array(laser_pose, dtype=np.float64)
        self.antenna_pose = np.array(antenna_pose, dtype=np.float64)

    def observations(self, k: int, features, landmarks, *, z, innov, S) -> None:
        """The q measurements used in scan k's update: their indices in the scan (q,), the
        landmark ids they updated (q,), z (q, 2), the innovations (q, 2) and the joint
        innovation covariance S (2q, 2q), of which each one's (2, 2) block is kept."""
        q = len(features)
        self.obs["scan"].append(np.full(q, k, np.int64))
        self.obs["feature"].append(np.asarray(features, np.int64))
        self.obs["landmark"].append(np.asarray(landmarks, np.int64))
        self.obs["z"].append(np.array(z).reshape(q, 2))
        self.obs["innov"].append(np.array(innov).reshape(q, 2))
        j = np.arange(q)
        self.obs["S"].append(S.reshape(q, 2, q, 2)[j, :, j, :])

    def scan_done(self, result, state, times: list[float]) -> None:
        """Scan k's estimate, counts, measurements with their status, track and circle radius
        (`result`: the loop's `slam.loop.ScanResult`), and phase times (`times`: perf_counter
        at the start and after each of the five steps)."""
        meas = result.meas
        k, z = meas.k, meas.z
        self.pose[k] = state.pose
        self.pose_cov[k] = state.pose_cov
        self.nis[k] = result.nis
        self.nis_dof[k] = 2 * result.n_used
        m = z.shape[0]
        self.counts["n_features"][k] = m
        self.counts["n_associated"][k] = result.n_used
        self.counts["n_tentative"][k] = result.n_pending
        self.counts["n_map"][k] = state.n_landmarks
        rows = self.meas
        self._block_of[k] = len(rows["scan"])
        rows["scan"].append(np.full(m, k, np.int64))
        rows["feature"].append(np.arange(m, dtype=np.int64))
        rows["z"].append(np.array(z).reshape(m, 2))
        rows["R"].append(np.array(meas.R).reshape(m, 2, 2))
        rows["status"].append(np.array(result.status, dtype=np.int64))
        rows["track"].append(np.array(result.track, dtype=np.int64))
        rows["radius"].append(np.array(meas.radius_m, dtype=np.float64))
        for key, a, b in zip(TIMING_KEYS[:5], times[:-1], times[1:]):
            self.timing[key][k] = b - a
        self.timing["total"][k] = times[-1] - times[0]

    def retrack(self, k: int, feature: int, track: int) -> None:
        """Give measurement `feature` of the already logged scan k the track id `track` (a
        window's new landmark: its earlier sightings)."""
        self.meas["track"][self._block_of[k]][int(feature)] = int(track)

    def build(
        self,
        state,
        history,
        *,
        start: str,
        features_method: str,
        association_method: str,
        config: dict,
        window_stats: dict | None = None,
        closures: list | None = None,
        closure_duplicates: list | None = None,
        existence=None,
        joint_dropped: list | None = None,
    ) -> SlamLog:
        """The `SlamLog`; existence: the run's `slam.existence_map.LandmarkExistence` (None
        without map policy "existence")."""
        ids = state.landmark_ids
        obs, meas, h = _joined(self.obs, _OBS_SHAPES), _joined(self.meas, _MEAS_SHAPES), history
        return SlamLog(
            scan_t=self.scan_t,
            pose=self.pose,
            pose_cov=self.pose_cov,
            pred_pose=h.pred_pose,
            pred_pose_cov=h.pred_pose_cov,
            landmark_xy=state.landmarks_xy.copy(),
            landmark_cov=state.landmark_covs,
            landmark_id=ids.copy(),
            landmark_first_scan=np.array([h.first_scan.get(int(i), -1) for i in ids], np.int64),
            landmark_n_obs=np.array([h.n_obs.get(int(i), 0) for i in ids], np.int64),
            obs_scan=obs["scan"],
            obs_feature=obs["feature"],
            obs_landmark=h.resolved(obs["landmark"]),
            obs_z=obs["z"],
            obs_innov=obs["innov"],
            obs_innov_cov=obs["S"],
            meas_scan=meas["scan"],
            meas_feature=meas["feature"],
            meas_z=meas["z"],
            meas_R=meas["R"],
            meas_status=h.resolved(meas["status"]),
            meas_track=h.resolved(meas["track"]),
            meas_radius_m=meas["radius"],
            scan_nis=self.nis,
            scan_nis_dof=self.nis_dof,
            scan_logdet=self.logdet,
            scan_skipped=self.skipped,
            **self.counts,
            timing_s=self.timing,
            start_pose=self.start_pose,
            start_cov=self.start_cov,
            laser_pose=self.laser_pose,
            odo_delta=h.odo_delta,
            odo_cov=h.odo_cov,
            final_x=state.x.copy(),
            final_P=state.P.copy(),
            start=start,
            features_method=features_method,
            association_method=association_method,
            config=config,
            window_stats=window_stats,
            antenna_pose=self.antenna_pose,
            closures=closures,
            closure_duplicates=closure_duplicates,
            meas_track_unmerged=meas["track"].copy() if h.alias else None,
            landmark_existence=None if existence is None else existence.of(ids),
            departures=list(self.departures),
            joint_dropped=joint_dropped,
        )


_OBS_SHAPES = {
    "scan": ((), np.int64),
    "feature": ((), np.int64),
    "landmark": ((), np.int64),
    "z": ((2,), np.float64),
    "innov": ((2,), np.float64),
    "S": ((2, 2), np.float64),
}
_MEAS_SHAPES = {
    "scan": ((), np.int64),
    "feature": ((), np.int64),
    "z": ((2,), np.float64),
    "R": ((2, 2), np.float64),
    "status": ((), np.int64),
    "track": ((), np.int64),
    "radius": ((), np.float64),
}


def _joined(blocks: dict[str, list], shapes: dict) -> dict[str, np.ndarray]:
    """Each column's blocks of rows as one array (empty, of its row shape, when none)."""
    return {
        k: np.concatenate(v) if v else np.zeros((0, *shapes[k][0]), shapes[k][1])
        for k, v in blocks.items()
    }
