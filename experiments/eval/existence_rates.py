"""The existence model's parameters measured on a run itself, without the reference map, the
GPS or the simulator's truth (`map_policy.policy = "existence"`, issue 41). From a run `lg`
of the sequence `seq` with the paper's map policy (confirm_scans), on the scans [a, b):

1. Pd from the detection rates the run measures (`beam_detection_rates`): every landmark of
   the final map associated in more than `established` scans (30: `ESTABLISHED`, as the
   map policy experiment's established landmarks), in each scan after it joined, placed by the
   run's pose in the laser frame, counts as expected with the number of its beams that reach
   its width unoccluded (`slam.existence.beam_evidence`, its circles' median radius), and as
   detected when a measurement updated it. min_beams: the fewest free beams whose detection
   rate is at least half the rate of the well-seen (>= `WELL_SEEN` free beams); pd_max: the
   rate pooled over min_beams free beams and more.
2. The clutter: false_per_scan, the circles the filter considered (not out of range, not in a
   skipped scan, not ambiguous) whose track never became a landmark, per scan used (none:
   half a circle over those scans, as the model needs a density above 0). It is the
   extractor's false-detection rate on the data at hand, where the simulator's (Table 4) is
   that of simulated parks without this park's clutter.
3. birth_prob: of the tracks started (a new tentative), the share that joined the map.
"""

from __future__ import annotations

import numpy as np

from experiments.errors import DataError
from slam import se2
from slam.existence import ExistenceConfig, beam_evidence
from slam.existence_map import DEFAULT_RADIUS_M
from slam.log import AMBIGUOUS, NEW_TENTATIVE, OUT_OF_RANGE, SKIPPED

__all__ = ["ESTABLISHED", "MAX_BEAMS", "WELL_SEEN", "beam_detection_rates", "derive_existence"]

ESTABLISHED = 30  # associated in more than this many scans: a landmark the run keeps seeing
WELL_SEEN = 10  # free beams: a trunk the extractor sees whole
MAX_BEAMS = 30  # free beams counted apart; more are pooled into the last bin


def _radius(lg, lid: int) -> float:
    r = lg.meas_radius_m[(lg.meas_track == lid) & np.isfinite(lg.meas_radius_m)]
    return float(np.median(r)) if r.size else DEFAULT_RADIUS_M


def beam_detection_rates(
    lg, seq, scans: tuple[int, int], established: int = ESTABLISHED
) -> tuple[np.ndarray, np.ndarray]:
    """(expected (MAX_BEAMS + 1,), detected (MAX_BEAMS + 1,)) by free beams (module doc, 1):
    the landmarks of the final map associated in more than `established` scans."""
    est = lg.landmark_n_obs > established
    ids, xy, first = lg.landmark_id[est], lg.landmark_xy[est], lg.landmark_first_scan[est]
    radius = np.array([_radius(lg, int(i)) for i in ids])
    seen = set(zip(lg.obs_scan.tolist(), lg.obs_landmark.tolist()))
    cfg = ExistenceConfig(max_range_m=float(seq.scan_max_range))
    expected = np.zeros(MAX_BEAMS + 1, np.int64)
    detected = np.zeros(MAX_BEAMS + 1, np.int64)
    max_range = min(float(seq.scan_max_range), float(lg.config["measurement"]["max_range_m"]))
    for k in range(scans[0], min(scans[1], lg.n_scans)):
        if lg.scan_skipped[k] or not ids.size:
            continue
        z, _ = se2.observe(lg.pose[k], xy, lg.laser_pose)
        scan = seq.scan(k)
        bearings = scan.angle_min_rad + scan.angle_increment_rad * np.arange(scan.ranges_m.size)
        fov = (z[:, 1] >= bearings[0]) & (z[:, 1] <= bearings[-1])
        j = np.flatnonzero(fov & (first < k) & (z[:, 0] <= max_range))
        if not j.size:
            continue
        ev = beam_evidence(scan.ranges_m, bearings, z[j, 0], z[j, 1], radius[j], cfg=cfg)
        free = np.minimum(ev.reach - ev.occluded, MAX_BEAMS)
        hit = np.array([(k, int(i)) in seen for i in ids[j]])
        np.add.at(expected, free, 1)
        np.add.at(detected, free, hit.astype(np.int64))
    return expected, detected


def derive_existence(lg, seq, scans: tuple[int, int], established: int = ESTABLISHED) -> dict:
    """The existence settings from the run `lg` (a confirm_scans run of `seq`) on `scans`
    (module doc): {"settings": {"map_policy.existence_<name>": value}, and the counts behind
    them}."""
    e, d = beam_detection_rates(lg, seq, scans, established)
    well = e[WELL_SEEN:].sum()
    if not well:
        raise DataError(
            f"derive_existence: no landmark of the run seen in more than {established} scans "
            f"was in view with {WELL_SEEN} free beams or more in scans {scans}: no detection "
            "rate to derive Pd from"
        )
    full = d[WELL_SEEN:].sum() / well
    rate = np.where(e > 0, d / np.maximum(e, 1), 0.0)
    min_beams = next(b for b in range(1, MAX_BEAMS + 1) if rate[b] >= full / 2 or b >= WELL_SEEN)
    pd_max = float(d[min_beams:].sum() / e[min_beams:].sum())
    in_half = (lg.meas_scan >= scans[0]) & (lg.meas_scan < scans[1])
    st = lg.meas_status
    considered = in_half & (st != OUT_OF_RANGE) & (st != SKIPPED) & (st != AMBIGUOUS)
    mapped = np.isin(lg.meas_track, lg.landmark_id) & (lg.meas_track >= 0)
    gone = [row[0] for row in (lg.departures or [])]
    mapped |= np.isin(lg.meas_track, gone) & (lg.meas_track >= 0)
    n_scans = int(np.count_nonzero(~lg.scan_skipped[scans[0] : scans[1]]))
    # none seen: half a circle over the scans used, a rate a run of that length cannot tell
    # from zero (the model needs a clutter density above 0)
    false_per_scan = max(int(np.count_nonzero(considered & ~mapped)), 0.5) / max(n_scans, 1)
    started = in_half & (st == NEW_TENTATIVE) & (lg.meas_track >= 0)
    tracks = np.unique(lg.meas_track[started])  # a tentative's id is its landmark's if it joins
    n_started = int(tracks.size)
    n_joined = int(np.count_nonzero(np.isin(tracks, lg.landmark_id) | np.isin(tracks, gone)))
    birth = n_joined / max(n_started, 1)
    return {
        "settings": {
            "map_policy.existence_pd_max": pd_max,
            "map_policy.existence_min_beams": int(min_beams),
            "map_policy.existence_false_per_scan": false_per_scan,
            "map_policy.existence_birth_prob": float(min(max(birth, 1e-6), 1.0)),
        },
        "expected_by_free_beams": e.tolist(),
        "detected_by_free_beams": d.tolist(),
        "tracks_started": n_started,
        "tracks_joined": n_joined,
        "scans_used": n_scans,
    }
