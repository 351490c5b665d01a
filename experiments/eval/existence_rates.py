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

Birth by range (`derive_birth_by_range`, used only when asked for):
3b. birth_prob_by_range: birth_prob of 3. per range bin [i bin_m, (i + 1) bin_m) up to the
   view's range, each started track in the bin of the range of the circle that started it
   (`slam.existence.range_bin`); a bin where no track started takes the pooled birth_prob.

Persistent clutter (`derive_persistent`, map policy `existence_clutter = "persistent"`), from
the same run's tracks that never became a landmark (the run's own verdict, as the clutter
rate's; no truth):
4. repeat_prob: how often such a circle is seen again in the next scan. The paper's policy
   drops a tentative at its first miss and maps it at its confirm_scans-th sighting, so a
   never-mapped track's sightings are a run of k < confirm_scans scans; with a chance p of
   being seen again each scan, P(k | k < C) is proportional to p^(k - 1) (a geometric run cut
   at C - 1), and p is its maximum-likelihood value (`truncated_geometric_p`; a run with no
   such track, a clean park, gives 0.5: nothing measured).
5. shape_sd_m: the spread of such a track's fitted centre beyond the noise: over its pairs of
   consecutive sightings, d = the world positions' difference (the run's pose after each
   scan; the pose error of consecutive scans is shared, so d carries the two measurements'
   noise G R G^T each, plus the odometry increment's), s^2 = max(0, mean(|d|^2 - trace of
   their covariance)) / 4 (two sightings, two axes).

Persistent clutter by range (`derive_repeat_by_range`, used only when asked for):
4b. repeat_prob_by_range: repeat_prob of 4. per range bin [i bin_m, (i + 1) bin_m) up to the
   view's range, each never-mapped track in the bin of its sightings' median range (the
   measured range; `slam.existence.range_bin`, the filter's rule); a bin with no such track
   takes the pooled repeat_prob of 4. It is the rate the non-tree hypothesis re-reports an
   object at that range, measured where it is, so it is not scaled by Pd's fall-off.

See-through (`derive_see_through`, used only when asked for; `docs/existence_keep_probe.py`):
6. see_through_q: the chance that a beam
   passes a real trunk's place in a scan where the trunk was not reported: of the beams that
   reach the established landmarks of 1. in the scans they were missed with at least min_beams
   free beams, the share of their free beams (not occluded: a beam that returned nearer than
   the trunk says nothing of it) that passed beyond them (no return, or one farther than the
   trunk's far side plus `ExistenceConfig.gap_m`). It is the rate of the "real" hypothesis's
   see-through factor q^n at a miss (`slam.existence`, step 3), measured where that factor
   applies.

See-through by range (`derive_see_through_by_range`, used only when asked for):
6b. see_through_q_by_range: the rate of 6. per range bin of the landmark (the run's pose),
   [i bin_m, (i + 1) bin_m) up to the view's range (`see_through_rates`: a bin with no free
   beam takes the pooled q of 6.; none passed: half a beam over those counted, as 6.).

Range fall-off (`derive_pd_range`, used only when asked for):
7. pd_max, pd_range_m, pd_range_scale_m: the maximum-likelihood logistic fall-off of the
   detection rate with range (`slam.existence`, "Range fall-off") over the views of 1. with at
   least min_beams free beams, binned by metre of range. On Victoria Park the rate at 2 free
   beams is about 0.8 at 10-30 m and 0.1 at 40-50 m: one pd_max over all ranges charges a far
   trunk's many misses as if it were near.
"""

from __future__ import annotations

import math

import numpy as np

from experiments.errors import DataError
from slam import se2
from slam.existence import ExistenceConfig, beam_evidence, range_bin
from slam.existence_map import DEFAULT_RADIUS_M
from slam.log import AMBIGUOUS, NEW_TENTATIVE, OUT_OF_RANGE, SKIPPED
from slam.tentatives import sighting

__all__ = [
    "ESTABLISHED",
    "MAX_BEAMS",
    "WELL_SEEN",
    "beam_detection_rates",
    "derive_birth_by_range",
    "derive_existence",
    "derive_pd_range",
    "derive_persistent",
    "derive_repeat_by_range",
    "derive_see_through",
    "derive_see_through_by_range",
    "range_detection_rates",
    "see_through_rates",
    "truncated_geometric_p",
]

ESTABLISHED = 30  # associated in more than this many scans: a landmark the run keeps seeing
WELL_SEEN = 10  # free beams: a trunk the extractor sees whole
MAX_BEAMS = 30  # free beams counted apart; more are pooled into the last bin


def _radius(lg, lid: int) -> float:
    r = lg.meas_radius_m[(lg.meas_track == lid) & np.isfinite(lg.meas_radius_m)]
    return float(np.median(r)) if r.size else DEFAULT_RADIUS_M


def _views(lg, seq, scans: tuple[int, int], established: int, footprint_steps: float = 0.0):
    """Per scan of `scans` in which some landmark of the final map associated in more than
    `established` scans is in view after it joined: (its beam evidence, free beams (clipped at
    MAX_BEAMS), whether a measurement updated it), arrays over those landmarks.
    footprint_steps: the see-through count's beam footprint (`slam.existence`, "Beam
    footprint"; 0: none)."""
    est = lg.landmark_n_obs > established
    ids, xy, first = lg.landmark_id[est], lg.landmark_xy[est], lg.landmark_first_scan[est]
    radius = np.array([_radius(lg, int(i)) for i in ids])
    seen = set(zip(lg.obs_scan.tolist(), lg.obs_landmark.tolist()))
    cfg = ExistenceConfig(max_range_m=float(seq.scan_max_range), footprint_steps=footprint_steps)
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
        yield ev, free, hit, z[j, 0]


def beam_detection_rates(
    lg, seq, scans: tuple[int, int], established: int = ESTABLISHED
) -> tuple[np.ndarray, np.ndarray]:
    """(expected (MAX_BEAMS + 1,), detected (MAX_BEAMS + 1,)) by free beams (module doc, 1):
    the landmarks of the final map associated in more than `established` scans."""
    expected = np.zeros(MAX_BEAMS + 1, np.int64)
    detected = np.zeros(MAX_BEAMS + 1, np.int64)
    for _, free, hit, _ in _views(lg, seq, scans, established):
        np.add.at(expected, free, 1)
        np.add.at(detected, free, hit.astype(np.int64))
    return expected, detected


def range_detection_rates(
    lg, seq, scans: tuple[int, int], edges_m: np.ndarray, established: int = ESTABLISHED
) -> tuple[np.ndarray, np.ndarray]:
    """(expected, detected), (len(edges_m) - 1, MAX_BEAMS + 1) int64 each: as
    `beam_detection_rates`, by range bin [edges_m[i], edges_m[i + 1]) of the landmark (m, the
    run's pose) and free beams; views outside the edges are not counted."""
    edges = np.asarray(edges_m, dtype=np.float64)
    expected = np.zeros((edges.size - 1, MAX_BEAMS + 1), np.int64)
    detected = np.zeros_like(expected)
    for _, free, hit, range_m in _views(lg, seq, scans, established):
        b = np.searchsorted(edges, range_m, side="right") - 1
        ok = (b >= 0) & (b < edges.size - 1)
        np.add.at(expected, (b[ok], free[ok]), 1)
        np.add.at(detected, (b[ok], free[ok]), hit[ok].astype(np.int64))
    return expected, detected


def derive_pd_range(
    lg, seq, scans: tuple[int, int], min_beams: int, established: int = ESTABLISHED
) -> dict:
    """Pd's range fall-off measured on the run (module doc, 7): the maximum-likelihood pd_max,
    pd_range_m and pd_range_scale_m of Pd(d) = pd_max / (1 + exp((d - pd_range_m) / scale))
    over the views of the established landmarks with at least min_beams free beams (in 1 m
    range bins up to the farthest view counted; grid steps 0.01, 0.5 m and 0.25 m)."""
    if not 1 <= min_beams <= MAX_BEAMS:
        raise DataError(
            f"derive_pd_range: min_beams must be 1-{MAX_BEAMS} (free beams are counted apart "
            f"up to MAX_BEAMS), got {min_beams!r}"
        )
    far = min(float(seq.scan_max_range), float(lg.config["measurement"]["max_range_m"]))
    if not math.isfinite(far) or far <= 0:
        raise DataError(
            "derive_pd_range: needs a finite range limit (the scans' max range or "
            f"measurement.max_range_m) to bin the views by range, got {far!r}"
        )
    edges = np.arange(0.0, far + 1.0, 1.0)
    e, d = range_detection_rates(lg, seq, scans, edges, established)
    n, k = e[:, min_beams:].sum(axis=1), d[:, min_beams:].sum(axis=1)
    if not n.sum():
        raise DataError(
            f"derive_pd_range: no established landmark was in view with {min_beams} free beams "
            f"or more in scans {scans}: no fall-off to derive"
        )
    last = int(np.flatnonzero(n)[-1]) + 1  # the grid spans the farthest view counted
    edges, n, k = edges[: last + 1], n[:last], k[:last]
    mid = 0.5 * (edges[:-1] + edges[1:])
    d50 = np.arange(1.0, edges[-1] + 0.5, 0.5)
    scale = np.arange(0.25, 20.0 + 0.25, 0.25)
    x = (mid[None, None, :] - d50[:, None, None]) / scale[None, :, None]
    f = 1.0 / (1.0 + np.exp(np.clip(x, -700.0, 700.0)))  # (d50, scale, bins)
    best = (-np.inf, 0.0, 0.0, 0.0)
    for pd in np.arange(0.05, 1.0, 0.01):
        p = np.clip(pd * f, 1e-12, 1.0 - 1e-12)
        ll = (k * np.log(p) + (n - k) * np.log1p(-p)).sum(axis=2)
        i, j = np.unravel_index(np.argmax(ll), ll.shape)
        if ll[i, j] > best[0]:
            best = (float(ll[i, j]), float(pd), float(d50[i]), float(scale[j]))
    return {
        "settings": {
            "map_policy.existence_pd_max": round(best[1], 2),
            "map_policy.existence_pd_range_m": best[2],
            "map_policy.existence_pd_range_scale_m": best[3],
        },
        "views": int(n.sum()),
        "detected": int(k.sum()),
        "log_likelihood": best[0],
    }


def _see_through_counts(
    lg, seq, scans, min_beams: int, *, established: int, footprint_steps: float, bin_m, n: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(through, reaching, free) beam counts (n,) int64 each, per range bin (`range_bin`; one
    walk over the scans): the views of `derive_see_through` (module doc, 6)."""
    through, reach, free_beams = (np.zeros(n, np.int64) for _ in range(3))
    for ev, free, hit, range_m in _views(lg, seq, scans, established, footprint_steps):
        missed = (free >= min_beams) & ~hit
        i = range_bin(range_m[missed], bin_m, n)
        np.add.at(through, i, ev.through[missed])
        np.add.at(reach, i, ev.reach[missed])
        np.add.at(free_beams, i, (ev.reach - ev.occluded)[missed])
    return through, reach, free_beams


def _pooled_q(through: np.ndarray, free_beams: np.ndarray, name: str, *, min_beams, scans) -> float:
    """max(through, 0.5) / free over every bin, at most 1; a DataError with no free beam."""
    if not int(free_beams.sum()):
        raise DataError(
            f"{name}: no established landmark was missed with {min_beams} free "
            f"beams or more in scans {scans}: no see-through rate to derive"
        )
    return float(min(max(int(through.sum()), 0.5) / int(free_beams.sum()), 1.0))


def derive_see_through(
    lg,
    seq,
    scans: tuple[int, int],
    min_beams: int,
    established: int = ESTABLISHED,
    *,
    footprint_steps: float = 0.0,
) -> dict:
    """see_through_q measured on the run (module doc, 6): of the free beams (reaching, not
    occluded by a nearer return) of the established landmarks (as `beam_detection_rates`
    places them) in the scans of `scans` where at least min_beams of them were free and no
    measurement updated the landmark, the share that passed beyond it (none passed: half a beam
    over those counted, a rate the run cannot tell from 0; the model needs q > 0). An occluded
    beam could neither pass nor hit: it is not evidence and is not counted (before 2026-11-29
    h41f it was, which biased q low by the occluded share: "missed_beams_reaching" keeps that
    count). footprint_steps: beams counted as passing beyond with the beam footprint the run
    will use (`map_policy.existence_see_through_footprint`; 0: none). What is counted is the
    filter's count with the footprint but without the see-through tolerance
    (`map_policy.existence_see_through_k`: the landmarks' covariances are not in the run's log,
    so no k-sigma region is applied here): with the tolerance on, the filter counts fewer
    see-through beams (a subset of these), and this q is an upper bound of the rate of the
    filter's count."""
    through, reach, free_beams = _see_through_counts(
        lg,
        seq,
        scans,
        min_beams,
        established=established,
        footprint_steps=footprint_steps,
        bin_m=1.0,
        n=1,
    )
    q = _pooled_q(through, free_beams, "derive_see_through", min_beams=min_beams, scans=scans)
    return {
        "settings": {"map_policy.existence_see_through_q": q},
        "missed_beams_reaching": int(reach.sum()),
        "missed_beams_free": int(free_beams.sum()),
        "missed_beams_through": int(through.sum()),
    }


def see_through_rates(through: np.ndarray, free: np.ndarray, pooled: float) -> np.ndarray:
    """(n,) q per bin from its see-through (n,) and free (n,) beam counts (module doc, 6b):
    max(through, 0.5) / free, at most 1; `pooled` where a bin has no free beam."""
    t = np.asarray(through, dtype=np.float64)
    f = np.asarray(free, dtype=np.float64)
    q = np.maximum(t, 0.5) / np.maximum(f, 1.0)
    return np.where(f > 0, np.minimum(q, 1.0), float(pooled))


def derive_see_through_by_range(
    lg,
    seq,
    scans: tuple[int, int],
    min_beams: int,
    bin_m: float = 10.0,
    *,
    footprint_steps: float = 0.0,
) -> dict:
    """see_through_q per range bin measured on the run (module doc, 6b), with the count of
    `derive_see_through` (footprint_steps and what is counted as there; a view's bin is
    `slam.existence.range_bin`, the filter's): {"settings":
    {"map_policy.existence_see_through_q_by_range": [...], "..._q_bin_m": bin_m}, counts}.
    A bin with no free beam takes the pooled q, from the bins' summed counts."""
    max_range = min(float(seq.scan_max_range), float(lg.config["measurement"]["max_range_m"]))
    n = max(int(math.ceil(max_range / bin_m)), 1)
    through, _, free_beams = _see_through_counts(
        lg,
        seq,
        scans,
        min_beams,
        established=ESTABLISHED,
        footprint_steps=footprint_steps,
        bin_m=bin_m,
        n=n,
    )
    name = "derive_see_through_by_range"
    pooled = _pooled_q(through, free_beams, name, min_beams=min_beams, scans=scans)
    q = see_through_rates(through, free_beams, pooled)
    return {
        "settings": {
            "map_policy.existence_see_through_q_by_range": [float(x) for x in q],
            "map_policy.existence_see_through_q_bin_m": float(bin_m),
        },
        "missed_beams_free": free_beams.tolist(),
        "missed_beams_through": through.tolist(),
    }


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


def derive_birth_by_range(lg, seq, scans: tuple[int, int], bin_m: float = 10.0) -> dict:
    """birth_prob per range bin measured on the run `lg` (a confirm_scans run of `seq`) on
    `scans` (module doc, 3b): {"settings": {"map_policy.existence_birth_prob_by_range": [...],
    "..._bin_m": bin_m}, the tracks started and joined per bin}. Each track falls in the bin of
    its first sighting (the circle that starts it). Each bin's share is clipped to
    [1e-6, 1 - 1e-6]: a bin whose every track joined would give 1, an existence no evidence
    lowers (the setting refuses it)."""
    if not (isinstance(bin_m, (int, float)) and 0.0 < bin_m < math.inf):
        raise DataError(f"derive_birth_by_range: bin_m must be finite and > 0, got {bin_m!r}")
    max_range = min(float(seq.scan_max_range), float(lg.config["measurement"]["max_range_m"]))
    n = max(int(math.ceil(max_range / bin_m)), 1)
    in_half = (lg.meas_scan >= scans[0]) & (lg.meas_scan < scans[1])
    rows = np.flatnonzero(in_half & (lg.meas_status == NEW_TENTATIVE) & (lg.meas_track >= 0))
    tracks, first = np.unique(lg.meas_track[rows], return_index=True)
    gone = [row[0] for row in (lg.departures or [])]
    joined = np.isin(tracks, lg.landmark_id) | np.isin(tracks, gone)
    b = range_bin(lg.meas_z[rows[first], 0], bin_m, n)
    started = np.bincount(b, minlength=n)
    hits = np.bincount(b, weights=joined.astype(np.float64), minlength=n)
    pooled = float(min(max(joined.sum() / max(tracks.size, 1), 1e-6), 1.0))
    share = np.where(started > 0, hits / np.maximum(started, 1), pooled)
    return {
        "settings": {
            "map_policy.existence_birth_prob_by_range": [
                float(min(max(x, 1e-6), 1.0 - 1e-6)) for x in share
            ],
            "map_policy.existence_birth_prob_bin_m": float(bin_m),
        },
        "tracks_started_by_bin": started.tolist(),
        "tracks_joined_by_bin": [int(x) for x in hits],
        "pooled_birth_prob": pooled,
    }


def truncated_geometric_p(k: np.ndarray, cut: int) -> float:
    """The maximum-likelihood p of runs k (>= 1) drawn with P(k) proportional to p^(k - 1) for
    k = 1 .. cut (module doc, 4), on a grid of 1e-4 in (0, 1); 0.5 / (runs + 1) when no run
    went past one scan (none seen again, or no run at all: a rate the sample cannot tell from 0;
    0.5 with no run)."""
    k = np.asarray(k, dtype=np.float64)
    if np.any(k < 1) or np.any(k > cut):
        raise DataError(f"truncated_geometric_p: needs runs in 1..{cut}, got {k.tolist()!r}")
    extra = float((k - 1).sum())
    if extra == 0 or cut == 1:
        return 0.5 / (k.size + 1)
    p = np.linspace(1e-4, 1 - 1e-4, 9999)
    norm = np.log(np.sum(p[:, None] ** np.arange(cut)[None, :], axis=1))
    return float(p[np.argmax(extra * np.log(p) - k.size * norm)])


def _never_mapped(lg, scans: tuple[int, int]) -> np.ndarray:
    """(n,) bool over the run's measurements: in `scans`, on a track that never became a
    landmark (nor left the map)."""
    in_half = (lg.meas_scan >= scans[0]) & (lg.meas_scan < scans[1]) & (lg.meas_track >= 0)
    gone = [row[0] for row in (lg.departures or [])]
    return in_half & ~np.isin(lg.meas_track, lg.landmark_id) & ~np.isin(lg.meas_track, gone)


def derive_repeat_by_range(lg, seq, scans: tuple[int, int], bin_m: float = 10.0) -> dict:
    """repeat_prob per range bin measured on the run `lg` (a confirm_scans run of `seq`) on
    `scans` (module doc, 4b): {"settings": {"map_policy.existence_repeat_prob_by_range":
    [...], "..._bin_m": bin_m}, the tracks per bin}. Each bin's rate is
    `truncated_geometric_p` of its tracks' runs (clipped as `derive_persistent`'s)."""
    if not (isinstance(bin_m, (int, float)) and 0.0 < bin_m < math.inf):
        raise DataError(f"derive_repeat_by_range: bin_m must be finite and > 0, got {bin_m!r}")
    max_range = min(float(seq.scan_max_range), float(lg.config["measurement"]["max_range_m"]))
    n = max(int(math.ceil(max_range / bin_m)), 1)
    never = _never_mapped(lg, scans)
    tracks, k = np.unique(lg.meas_track[never], return_counts=True)
    cut = max(int(lg.config["map_policy"]["confirm_scans"]) - 1, 1)
    pooled = truncated_geometric_p(np.minimum(k, cut), cut)
    rng = np.array([np.median(lg.meas_z[never & (lg.meas_track == t), 0]) for t in tracks])
    b = range_bin(rng, bin_m, n) if tracks.size else np.zeros(0, np.int64)
    rates, counts = [], []
    for i in range(n):
        runs = np.minimum(k[b == i], cut)
        counts.append(int(runs.size))
        rates.append(truncated_geometric_p(runs, cut) if runs.size else pooled)
    return {
        "settings": {
            "map_policy.existence_repeat_prob_by_range": [float(p) for p in rates],
            "map_policy.existence_repeat_prob_bin_m": float(bin_m),
        },
        "never_mapped_tracks_by_bin": counts,
        "pooled_repeat_prob": pooled,
    }


def derive_persistent(lg, scans: tuple[int, int]) -> dict:
    """The persistent clutter's settings from the run `lg` (a confirm_scans run) on `scans`
    (module doc, 4-5): {"settings": {"map_policy.existence_<name>": value}, and the counts}.
    A never-mapped track seen in more scans than confirm_scans - 1 (a window associator's, or
    one with gaps) does not fit the truncated geometric model: it counts as confirm_scans - 1
    sightings, and how many were so clipped is reported ("clipped_tracks")."""
    in_half = (lg.meas_scan >= scans[0]) & (lg.meas_scan < scans[1]) & (lg.meas_track >= 0)
    gone = [row[0] for row in (lg.departures or [])]
    never = in_half & ~np.isin(lg.meas_track, lg.landmark_id) & ~np.isin(lg.meas_track, gone)
    tracks, k = np.unique(lg.meas_track[never], return_counts=True)
    cut = int(lg.config["map_policy"]["confirm_scans"]) - 1
    p = truncated_geometric_p(np.minimum(k, max(cut, 1)), max(cut, 1))
    excess = []
    for t in tracks[k >= 2].tolist():
        rows = np.flatnonzero(never & (lg.meas_track == t))
        rows = rows[np.argsort(lg.meas_scan[rows])]
        at = []
        for r in rows:
            i = int(lg.meas_scan[r])
            xy, C = sighting(
                lg.pose[i], np.zeros((3, 3)), lg.meas_z[r], lg.meas_R[r], lg.laser_pose
            )
            at.append((i, xy, C, float(lg.meas_z[r, 0])))
        for (i, x1, C1, _), (j, x2, C2, d) in zip(at, at[1:]):
            if j != i + 1:
                continue
            # the increment's position noise, and its heading noise carried to the range
            odo = float(np.trace(lg.odo_cov[j][:2, :2]) + lg.odo_cov[j][2, 2] * d**2)
            excess.append(float(np.sum((x2 - x1) ** 2) - np.trace(C1 + C2) - odo))
    shape_var = max(float(np.mean(excess)), 0.0) / 4.0 if excess else 0.0
    return {
        "settings": {
            "map_policy.existence_repeat_prob": p,
            "map_policy.existence_shape_sd_m": float(np.sqrt(shape_var)),
        },
        "never_mapped_tracks": int(tracks.size),
        "never_mapped_runs": np.bincount(k, minlength=max(cut, 1) + 1)[1:].tolist(),
        "consecutive_pairs": len(excess),
        "clipped_tracks": int(np.count_nonzero(k > max(cut, 1))),
    }
