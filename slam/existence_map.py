"""`map_policy.policy = "existence"`: every landmark and tentative of a run carries its existence,
the probability that it is a real trunk (`slam.existence` holds the model), kept here by id.

Each scan, after the association and before the filter's update (`LandmarkExistence.update`,
called by the loop), on the predicted state:
1. the landmarks and tentatives predicted inside the view (no margins) are placed in the laser
   frame and the scan's beams give each its reach, occlusion and see-through counts
   (`slam.existence.beam_evidence`), its radius the last circle associated with it;
2. the association says which were detected; each detection's likelihood is N(nu; 0, S) with
   S = H C H^T + R of the candidate's [pose, point] block, as the association gated it;
3. Bayes' rule updates their existence (`slam.existence.update_existence`); landmarks the loop
   closure hid from the association learn nothing in that scan.
With `existence_see_through_k` > 0 the beams of step 1 are counted with the see-through
tolerance (`slam.existence`, "See-through tolerance"), each place's range and bearing sd from
its [pose, point] covariance (a tentative's own, fused with `existence_fuse_tentatives`,
beside the pose's). With `existence_see_through_footprint` > 0 a see-through beam's footprint
(that many beam steps either side of its ray, + k sd_bearing with the tolerance) must lie inside
the trunk (`slam.existence`, "Beam footprint"); a landmark's radius is the last circle's.
With `existence_see_through_q_by_range` a landmark's see-through rate is its range bin's
(`slam.existence.see_through_q`). With `existence_repeat_prob_by_range` (persistent clutter) a
landmark's or window track's non-tree repeat rate is its range bin's, not repeat_prob scaled by
the range fall-off (`slam.existence.repeat_rate`). With `existence_birth_prob_by_range` a new
tentative (or a window track) starts at its range bin's birth probability.
The map managers read it (`slam.map_managers`): a tentative joins the map when its existence
reaches `join_prob` (in a scan it was seen in), a window track joins when the existence of its
sightings (`track_existence`) does, and a landmark whose existence falls below `remove_prob`
leaves the map, reported in `MapDecisions.removed` for the loop to marginalise. A new
tentative starts at `map_policy.existence_birth_prob`. With kept tentatives
(`existence_keep_tentatives`) and `existence_unreached_scans` N > 0, a tentative the sensor
model gave Pd 0 (outside the view or the reach, or with fewer than `min_beams` free beams:
hidden behind a nearer return) and that was not detected, in N consecutive scans, is dropped
too (`unreached`): it could not have been confirmed in those scans. Its existence may still
have fallen meanwhile, by the beams seen through its place.
"""

from __future__ import annotations

import math

import numpy as np

from slam import se2
from slam.config import MapPolicy
from slam.ekf import Filter, landmark_columns
from slam.existence import (
    BeamEvidence,
    ExistenceConfig,
    beam_evidence,
    clutter_density,
    detection_probability,
    falloff,
    gaussian_likelihood,
    range_bin,
    repeat_rate,
    see_through_q,
    update_existence,
    update_existence_persistent,
)

__all__ = ["DEFAULT_RADIUS_M", "LandmarkExistence", "radii"]


def _mean_nis_likelihood(S: np.ndarray, S_obj: np.ndarray) -> float:
    """N(nu; 0, S_obj) at an innovation of S's mean NIS 2 (nu^T S^-1 nu = 2), taken along S's
    principal axes equally: the non-tree likelihood of a typical window track's sighting."""
    w, V = np.linalg.eigh(S)
    nu = V @ np.sqrt(w)  # nu^T S^-1 nu = 2
    m = float(nu @ np.linalg.solve(S_obj, nu))
    return math.exp(-0.5 * m) / (2.0 * math.pi * math.sqrt(max(np.linalg.det(S_obj), 1e-300)))


# A landmark's radius before a circle with one was associated with it (published detections
# give diameters; a source without them gets this): a Victoria Park trunk's, 0.15 m.
DEFAULT_RADIUS_M = 0.15


def radii(meas) -> np.ndarray:
    """(m,) the radius of each circle of a scan's measurements (NaN where unknown)."""
    if meas.features is None:
        return np.full(meas.z.shape[0], math.nan)
    return meas.radius_m


class LandmarkExistence:
    """The existence of every landmark and tentative of a run, by id (module doc). view: the
    laser's `View` (fov, max_range); laser: T_vehicle_laser (3,)."""

    def __init__(self, policy: MapPolicy, view, laser: np.ndarray) -> None:
        self.view, self.laser = view, np.asarray(laser, dtype=np.float64)
        self.cfg = ExistenceConfig(
            pd_max=float(policy.existence_pd_max),
            min_beams=int(policy.existence_min_beams),
            see_through_q=float(policy.existence_see_through_q),
            max_range_m=float(view.max_range),
            join_prob=float(policy.existence_join_prob),
            remove_prob=float(policy.existence_remove_prob),
            pd_range_m=float(policy.existence_pd_range_m),
            pd_range_scale_m=float(policy.existence_pd_range_scale_m),
            see_through_k=float(policy.existence_see_through_k),
            footprint_steps=float(policy.existence_see_through_footprint),
            q_by_range=policy.existence_see_through_q_by_range,
            q_bin_m=float(policy.existence_see_through_q_bin_m),
            repeat_by_range=policy.existence_repeat_prob_by_range,
            repeat_bin_m=float(policy.existence_repeat_prob_bin_m),
        )
        fov = float(view.fov[1] - view.fov[0])
        self.kappa = clutter_density(
            float(policy.existence_false_per_scan), float(view.max_range), max(fov, 1e-9)
        )
        self.birth = float(policy.existence_birth_prob)
        self.birth_table = np.asarray(policy.existence_birth_prob_by_range, dtype=np.float64)
        self.birth_bin_m = float(policy.existence_birth_prob_bin_m)
        # map_policy.existence_clutter "persistent": re-sightings weighed against a non-tree
        # object at the place (`slam.existence`, "Persistent clutter"); None: uniform clutter
        self.repeat = (
            float(policy.existence_repeat_prob)
            if policy.existence_clutter == "persistent"
            else None
        )
        self.shape_var = float(policy.existence_shape_sd_m) ** 2
        self.r: dict[int, float] = {}
        self.radius: dict[int, float] = {}
        # kept tentatives out of reach: consecutive scans without a reaching beam, by id
        limit = policy.existence_unreached_scans if policy.existence_keep_tentatives else 0
        self.unreached_limit = int(limit)
        self.out_of_reach: dict[int, int] = {}
        # a list to record every scan's update in (diagnosis; None: nothing recorded): per
        # scan a dict of (n,) arrays over the landmarks and tentatives it updated
        self.trace: list | None = None

    def born(self, lid: int, radius_m: float, range_m: float = math.nan) -> None:
        """A new tentative `lid` seen with a circle of radius_m (NaN: unknown) at range_m (the
        birth table's bin; NaN or no table: the single birth probability)."""
        self.r[int(lid)] = self._birth_at(range_m)
        self._radius(lid, radius_m)

    def _birth_at(self, range_m: float) -> float:
        """The birth probability of a track starting at range_m (module doc)."""
        if not self.birth_table.size or not math.isfinite(range_m):
            return self.birth
        i = range_bin(np.array([range_m]), self.birth_bin_m, self.birth_table.size)[0]
        return float(self.birth_table[i])

    def of(self, ids) -> np.ndarray:
        """(n,) the existence of these ids (NaN for an id never seen)."""
        return np.array([self.r.get(int(i), math.nan) for i in ids], np.float64)

    def joins(self, ids) -> np.ndarray:
        """(n,) bool: existence at or above join_prob."""
        return self.of(ids) >= self.cfg.join_prob

    def leaves(self, ids) -> np.ndarray:
        """(n,) bool: existence below remove_prob."""
        return self.of(ids) < self.cfg.remove_prob

    def unreached(self, ids) -> np.ndarray:
        """(n,) bool: tentatives out of every beam's reach for `existence_unreached_scans`
        consecutive scans (none when that is 0 or tentatives are not kept)."""
        if not self.unreached_limit:
            return np.zeros(len(ids), bool)
        n = np.array([self.out_of_reach.get(int(i), 0) for i in ids], np.int64)
        return n >= self.unreached_limit

    def _count_unreached(self, t_ids: np.ndarray, reached: np.ndarray) -> None:
        """One scan of the tentatives' out-of-reach counts (reached: ids with Pd > 0)."""
        if not self.unreached_limit:
            return
        hit = set(reached.tolist())
        self.out_of_reach = {
            i: 0 if i in hit else self.out_of_reach.get(i, 0) + 1 for i in t_ids.tolist()
        }

    def track_existence(
        self,
        n_sightings: int,
        R: np.ndarray,
        range_m: float = math.inf,
        first_range_m: float | None = None,
    ) -> float:
        """The existence of a window track seen in n_sightings scans, each a detection with the
        likelihood of an innovation of NIS 2 (its mean) under S = 2 R (two sightings' noise);
        range_m: its latest sighting's range (the range fall-off of Pd, persistent clutter's
        shape term); first_range_m: its first sighting's, the circle that starts it, whose
        range bin gives its birth (None: range_m).
        Against persistent clutter a track gains about pd_max / repeat_prob a sighting, and a
        window holds at most window_scans of them: it joins only when that is enough (the
        single-scan associator's tentatives have no such limit)."""
        S = 2.0 * np.asarray(R, dtype=np.float64)
        g = math.exp(-1.0) / (2.0 * math.pi * math.sqrt(max(np.linalg.det(S), 1e-300)))
        f = falloff(np.array([float(range_m)]), self.cfg)  # a detection's Pd: pd_max f(d)
        ratio = self.cfg.pd_max * (1.0 if f is None else float(f[0])) * g / self.kappa
        if self.repeat is not None:  # persistent clutter: against an object at the place
            J = np.diag([1.0, 1.0 / max(float(range_m), 1e-3) ** 2])  # world xy -> range, bearing
            repeat = self.repeat
            if self.cfg.repeat_by_range:  # the range bin's rate against Pd's fall-off
                repeat = float(repeat_rate(np.array([float(range_m)]), self.cfg)[0])
                repeat /= 1.0 if f is None else max(float(f[0]), 1e-300)
            ratio = self.cfg.pd_max * g / (repeat * _mean_nis_likelihood(S, S + self.shape_var * J))
        # in log-odds: ratio ** n overflows (an OverflowError, not inf) for tiny clutter rates
        birth = self._birth_at(float(range_m if first_range_m is None else first_range_m))
        lo = math.log(max(birth, 1e-300)) - math.log(max(1.0 - birth, 1e-300))
        lo += max(n_sightings - 1, 0) * math.log(max(ratio, 1e-300))
        return 1.0 / (1.0 + math.exp(-lo)) if lo > -700.0 else 0.0

    def track(self, lid: int, r: float, radius_m: float) -> None:
        """A window track joined the map as landmark lid with existence r."""
        self.r[int(lid)] = float(r)
        self._radius(lid, radius_m)

    def _radius(self, lid: int, radius_m: float) -> None:
        if math.isfinite(radius_m) and radius_m > 0:
            self.radius[int(lid)] = float(radius_m)

    def update(self, state: Filter, meas, a, tentatives=None, hidden=None) -> None:
        """One scan's update (module doc) on the predicted state, with the association `a`
        (`slam.map_managers.ScanAssociation`); tentatives: the `slam.tentatives.Tentatives`
        (None: none, the window's); hidden: the landmarks closure hid (mask or None)."""
        n_lm = state.landmark_ids.size
        ids = state.landmark_ids.astype(np.int64)
        xy = state.landmarks_xy
        t_ids = np.zeros(0, np.int64) if tentatives is None else tentatives.ids
        if tentatives is not None and len(tentatives):
            xy = np.concatenate([xy, tentatives.xy])
            ids = np.concatenate([ids, t_ids])
        if not ids.size:
            return
        z_hat, H5 = se2.observe(state.pose, xy, self.laser)
        look = self.view.contains(z_hat, margins=False)
        if hidden is not None:
            look[:n_lm] &= ~np.asarray(hidden, bool)
        detected, g, g_obj = self._detections(state, meas, a, tentatives, z_hat=z_hat, H5=H5)
        look |= detected
        idx = np.flatnonzero(look)
        if not idx.size:
            self._count_unreached(t_ids, idx)
            return
        radius = np.array([self.radius.get(int(i), DEFAULT_RADIUS_M) for i in ids[idx]])
        sig = None
        if self.cfg.see_through_k > 0:  # the see-through tolerance (`slam.existence`)
            sig = self._place_sigma(state, tentatives, idx, H5[idx])
        ev = self._evidence(meas.scan, z_hat[idx], radius, sig)
        pd = detection_probability(ev, z_hat[idx, 0], np.ones(idx.size, bool), self.cfg)
        # a landmark the association paired was seen, whatever the beams say of its reach
        f = falloff(z_hat[idx, 0], self.cfg)
        pd = np.where(detected[idx], self.cfg.pd_max if f is None else self.cfg.pd_max * f, pd)
        self._count_unreached(t_ids, ids[idx][pd > 0])
        r = r_before = self.of(ids[idx])
        r = np.where(np.isfinite(r), r, self.birth)
        q = see_through_q(z_hat[idx, 0], self.cfg) if self.cfg.q_by_range else None
        if self.repeat is None:
            r = update_existence(
                r, pd, detected[idx], g[idx], ev.through, kappa=self.kappa, cfg=self.cfg, q=q
            )
        else:
            repeat, f_repeat = self.repeat, f
            if self.cfg.repeat_by_range:  # the bin's rate, measured where it is: no f(d)
                repeat, f_repeat = repeat_rate(z_hat[idx, 0], self.cfg), None
            r = update_existence_persistent(
                r,
                pd,
                detected[idx],
                g[idx],
                g_obj[idx],
                through=ev.through,
                repeat_prob=repeat,
                cfg=self.cfg,
                falloff=f_repeat,
                q=q,
            )
        for lid, v in zip(ids[idx].tolist(), r.tolist()):
            self.r[lid] = v
        if self.trace is not None:
            free, k = ev.reach - ev.occluded, meas.k
            self.trace.append(
                {
                    "scan": k,
                    "id": ids[idx],
                    "range_m": z_hat[idx, 0],
                    "free": free,
                    "reach": ev.reach,
                }
                | {"through": ev.through, "pd": pd, "detected": detected[idx]}
                | {"r_before": r_before, "r_after": r}
            )

    def _evidence(self, scan, z_hat: np.ndarray, radius: np.ndarray, sig) -> BeamEvidence:
        """The beam evidence of the landmarks predicted at z_hat (n, 2) (`beam_evidence`; sig:
        their place's sd for the see-through tolerance, or None)."""
        n = z_hat.shape[0]
        if scan is None:  # no beams: in view means reachable, nothing seen through
            reach, through = np.full(n, self.cfg.min_beams, np.int64), np.zeros(n, np.int64)
            return BeamEvidence(reach, np.zeros(n, np.int64), through)
        ranges = np.asarray(scan.ranges_m, dtype=np.float64)
        bearings = scan.angle_min_rad + scan.angle_increment_rad * np.arange(ranges.size)
        return beam_evidence(
            ranges, bearings, z_hat[:, 0], z_hat[:, 1], radius, cfg=self.cfg, place_sigma=sig
        )

    @staticmethod
    def _pose_point_covs(state: Filter, tentatives, idx: np.ndarray) -> np.ndarray:
        """(n, 5, 5) the [pose, point] covariance of [landmarks, tentatives][idx]: a landmark's
        block of the state, a tentative's (fused) covariance beside the pose's, uncorrelated,
        as the association offers them."""
        n_lm = state.landmark_ids.size
        C5 = np.zeros((idx.size, 5, 5))
        lm = idx < n_lm
        if lm.any():
            C5[lm] = state.cov(landmark_columns(idx[lm]))
        if (~lm).any():
            C5[~lm, :3, :3] = state.pose_cov
            C5[~lm, 3:, 3:] = tentatives.cov[idx[~lm] - n_lm]
        return C5

    @staticmethod
    def _place_sigma(state: Filter, tentatives, idx: np.ndarray, H: np.ndarray) -> np.ndarray:
        """(n, 2) the sd of the predicted (range, bearing) of [landmarks, tentatives][idx]
        from their [pose, point] covariance (H (n, 2, 5) its Jacobian): a landmark's 5 x 5 block
        of the state, a tentative's (fused) covariance beside the pose's, uncorrelated, as the
        association offers them."""
        C5 = LandmarkExistence._pose_point_covs(state, tentatives, idx)
        S = np.einsum("nij,njk,nlk->nil", H, C5, H)
        return np.sqrt(np.maximum(np.stack([S[:, 0, 0], S[:, 1, 1]], axis=1), 0.0))

    def _detections(self, state, meas, a, tentatives, *, z_hat, H5):
        """(detected (L,) bool, likelihood (L,), likelihood under a non-tree object (L,)) of
        [landmarks, tentatives] from the association; the radii of the detecting circles are
        remembered."""
        L, n_lm = z_hat.shape[0], state.landmark_ids.size
        detected, g, g_obj = np.zeros(L, bool), np.zeros(L), np.zeros(L)
        rows = np.flatnonzero(a.assign >= 0)
        if not rows.size:
            return detected, g, g_obj
        j = a.assign[rows]
        cand = np.concatenate([a.lm_idx, n_lm + a.t_idx]).astype(np.int64)[j]  # into z_hat
        C5 = self._pose_point_covs(state, tentatives, cand)
        H = H5[cand]
        S = np.einsum("nij,njk,nlk->nil", H, C5, H) + meas.R[rows]
        nu = meas.z[rows] - z_hat[cand]
        nu[:, 1] = (nu[:, 1] + np.pi) % (2.0 * np.pi) - np.pi
        detected[cand] = True
        g[cand] = gaussian_likelihood(nu, S)
        if self.repeat is not None:  # the object's shape spreads its centre: + H_l Sc H_l^T
            Hl = H[:, :, 3:]
            g_obj[cand] = gaussian_likelihood(nu, S + self.shape_var * Hl @ Hl.transpose(0, 2, 1))
        ids = np.concatenate(
            [state.landmark_ids, np.zeros(0, np.int64) if tentatives is None else tentatives.ids]
        )
        for c, rad in zip(cand.tolist(), radii(meas)[rows].tolist()):
            self._radius(int(ids[c]), rad)
        return detected, g, g_obj
