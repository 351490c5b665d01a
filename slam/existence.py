"""Landmark existence: the probability that a landmark is a real trunk, updated every scan from
what the laser did and did not report (issue 41; the run loop uses it through
`slam.existence_map`, map policy "existence").

A landmark (tentative or mapped) carries r, the probability that it is a static trunk the
extractor can see. Each scan:

1. **Prediction.** r <- survival * r: a trunk is still there one scan later with probability
   `survival` (1: trees do not move; below 1 to let a parked car or a standing person fade).
2. **Detection probability** (`beam_evidence`, `detection_probability`). From the sensor
   model, for each landmark at range d and bearing b with radius a, in the scan's beams:
   - reach: the beams whose bearing lies within the trunk's angular half-width asin(a / d) of
     b (with the landmark's bearing uncertainty added to the half-width if given); a trunk
     at 30 m of radius 0.15 m spans 0.57 deg, one or two beams of 0.5 deg;
   - occluded: of them, those whose return is nearer than d - a - `gap_m` (something in
     front hides the trunk from that beam);
   - see-through: of them, those with no return or a return beyond d + a + `gap_m` (the beam
     passed where the trunk should be).
   Pd = pd_max when at least `min_beams` of the reaching beams are not occluded (the
   extractor needs that many beams on a trunk to fit a circle), else 0; and 0 out of the
   field of view or beyond `max_range_m`.
   **Range fall-off** (`pd_range_m` finite; inf, the default, leaves Pd as above): the
   extractor reports what enough beams reach less often the farther it is (on Victoria Park,
   trunks with 2 free beams: ~0.8 of the scans at 10-30 m, ~0.5 at 30-40 m, ~0.1 at 40-50 m),
   so Pd = pd_max f(d) with f(d) = 1 / (1 + exp((d - pd_range_m) / pd_range_scale_m)), the
   range where it halves and how fast; a detection's Pd is pd_max f(d) too. Against
   persistent clutter the object's repeat_prob falls the same way (repeat_prob f(d): the
   extractor sees any object less far away), so a far sighting or miss weighs what a near
   one does, scaled by what the extractor can still report there (`falloff`).
3. **Update** (`update_existence`), Bayes' rule on the two hypotheses "real" / "not real":
   - detected (a measurement associated, with likelihood g = N(nu; 0, S) under "real"):
     r' = r Pd g / (r Pd g + (1 - r) kappa), with kappa the clutter density (false
     detections per m per rad, `clutter_density`): under "not real" the measurement is
     clutter;
   - missed: r' = r (1 - Pd) q^n / (r (1 - Pd) q^n + (1 - r)), where n is the number of
     see-through beams and q (`see_through_q`) the chance that a beam passes a real trunk's
     place (the landmark's position error, a beam grazing its edge); under "not real" the
     beams pass freely (likelihood 1).
   A landmark with Pd = 0 and no see-through beam keeps its r: nothing was learnt.
   **Persistent clutter** (`update_existence_persistent`, map policy `existence_clutter =
   "persistent"`). The clutter density above treats every false circle as a fresh draw over
   the whole measurement space, so a second sighting at the same place is a million times more
   likely under "real" and anything the extractor reports twice joins: a person's legs, a
   bush. They are real objects, not trees. Here "not a tree" is an object at the landmark's
   place that the extractor reports again, in a scan whose beams reach it, with probability
   `repeat_prob` (measured on a run: how often a circle that never became a landmark is seen
   again in the next scan), its circle's centre spread by the object's shape with sd
   `shape_sd_m` per axis (a bush's or a car corner's fitted centre moves with the view):
     detected: r' = r Pd g / (r Pd g + (1 - r) repeat_prob g_o), g_o = N(nu; 0, S + H Sc H^T)
     missed:   r' = r (1 - Pd) q^n / (r (1 - Pd) q^n + (1 - r) (1 - repeat_prob)),
   with repeat_prob 0 where Pd is 0 (neither reports what the beams cannot reach). A trunk
   gains about Pd / repeat_prob a scan and more when its sightings hold still; an object seen
   in a few scans as the car passes, or whose centre wanders, does not reach join_prob. The
   birth (a new tentative) is unchanged: b / (b + kappa) against the one-off clutter.
   **Intermittent detection** (map policy `existence_keep_tentatives`). The paper's policy
   drops a tentative at its first miss; on Victoria Park the extractor reports a tree in about
   60% of the scans whose beams reach it, so a tree must string together an unbroken run of
   sightings. Kept through its misses, a tentative's log-odds change each scan by
   log(Pd g / c) when seen (c: kappa, or repeat_prob g_o against persistent clutter) and by
   log((1 - Pd) q^n / (1 - c')) when missed (c' = 0, or repeat_prob), where Pd is the sensor
   model's (0 where the beams cannot reach it: an unreachable miss costs nothing). A tree seen
   at rate p of its reachable scans gains on average p log(Pd g / c) + (1 - p) log((1 - Pd) /
   (1 - c')) a scan and joins once the sum passes logit(join_prob) - logit(birth); a one-off
   false circle is missed in every following scan that reaches it and falls below remove_prob
   after logit(birth) - logit(remove_prob) over -log((1 - Pd) / (1 - c')) such scans.
   **See-through tolerance** (`see_through_k` k > 0, the filter passes each landmark's
   predicted range and bearing sd, sd_r and sd_b, from its position's and the pose's
   covariance). A landmark placed with an error of a few dm is missed by beams that pass
   the real trunk's place, or hit it a little farther than the landmark: such beams are not
   evidence that nothing is there. With the tolerance a reaching beam counts as see-through
   only when its return lies beyond the k-sigma region grown by the radius and the gap (range
   > d + a + gap_m + k sd_r), and no beam counts when any beam whose bearing is within the
   trunk's half-width + k sd_b returned inside that region (|range - d| <= a + gap_m + k sd_r:
   the trunk may be what it hit). k is a chi-square quantile, not a tuned value: the map
   policy's `existence_see_through_k` names it (sqrt(chi2_2(0.95)) = 2.448, the half-width of
   the 95% ellipse's projection on an axis).
   **Beam footprint** (`footprint_steps` f > 0; 0, the default: none). A beam's bearing is
   known to within its share of the angular grid, so a beam at bearing offset db from a
   landmark of radius a at range d may pass anywhere within f x the beam step of db: at 35 m a
   0.5 deg step is 0.31 m, a trunk's width, and a beam whose nominal ray crosses the trunk's
   edge may have passed beside it. With the footprint a reaching beam counts as see-through
   only when its whole footprint lies inside the trunk's disk, grown by nothing and shrunk by
   the landmark's bearing uncertainty: |db| + f step + k sd_b <= asin(a / d) (k sd_b with the
   see-through tolerance; the rest of the tolerance unchanged). f = 0.5 is half the step, the
   ray's own angular uncertainty (the Victoria Park data state no beam divergence). At 35 m a
   trunk of radius 0.15 m (asin = 0.246 deg) then has no see-through beam at a 0.5 deg step
   (0.246 - 0.25 < 0): the grid is too coarse there to say that a beam passed it.
   **See-through rate by range** (`q_by_range` non-empty; (), the default: one q). The chance
   that a beam passes a real trunk's place grows with range (the beam step and the position
   error grow against the trunk's width), so one q measured over every range charges a near
   trunk's see-through beams too little and a far one's too much. With a table, a landmark at
   range d uses q_by_range[i], i = floor(d / q_bin_m) (the last bin's beyond the table):
   the rate measured per bin on the run's own established landmarks
   (`experiments.eval.existence_rates.derive_see_through_by_range`).
   **Repeat rate by range** (`repeat_by_range` non-empty; (), the default: repeat_prob scaled
   by the range fall-off). Against persistent clutter a detection weighs Pd g against the
   non-tree object's re-report rate: with one repeat_prob scaled by the trees' own fall-off
   f(d) the ratio Pd / repeat is the same at every range, so a far sighting (a thin object
   seen by 1-3 beams) is as strong evidence of a tree as a near one. With a table, a landmark
   at range d is weighed against repeat_by_range[i], i = floor(d / repeat_bin_m) (the last
   bin's beyond the table), not scaled by f(d): the rate measured per bin on the run's own
   never-mapped tracks, so a detection weighs Pd(d) / repeat(d), the extractor's false
   re-reports where they are (`experiments.eval.existence_rates.derive_repeat_by_range`).
4. **Decisions** (`decide`): a tentative joins the map when r >= `join_prob` ("at least this
   probable that it is a real trunk"); a landmark is removed when r < `remove_prob` ("less
   probable than this that it is real"). A new tentative starts at `initial_existence(birth,
   kappa)` = b / (b + kappa): of the circles seen at a place where nothing was mapped, the
   share that are new trunks, when new trunks appear with density b and clutter with kappa.

Interface (all vectorised over L landmarks; arrays are numpy float64 unless said):
    cfg = ExistenceConfig(pd_max=0.9, min_beams=2, see_through_q=0.1, ...)
    ev = beam_evidence(ranges_m (B,), bearings_rad (B,), lm_range_m (L,), lm_bearing_rad (L,),
                       radius_m (L,), cfg)       -> BeamEvidence(reach, occluded, through) (L,)
    pd = detection_probability(ev, lm_range_m, in_fov (L,) bool, cfg)        -> (L,)
    kappa = clutter_density(false_per_scan, max_range_m, fov_rad)           -> float
    r = predict_existence(r, cfg)
    r = update_existence(r, pd, detected (L,) bool, likelihood (L,), ev.through, kappa, cfg)
    join, remove = decide(r, cfg)                                           -> (L,) bool each

How it replaces the map policy's counts (`slam.existence_map`): `confirm_scans`
(a tentative joins after that many sightings) becomes `join_prob`, and the pruner's
`prune_hit_ratio` / `prune_after_expected` / `prune_range_m` (remove a landmark seen in too
few of the scans it was in view within a range) become `remove_prob` with Pd from the sensor
model: a far thin object seen by one beam has Pd near 0, so missing it costs nothing, while a
trunk that beams pass through loses existence fast. The pure-numpy functions here import
nothing of the filter loop.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

__all__ = [
    "BeamEvidence",
    "ExistenceConfig",
    "beam_evidence",
    "clutter_density",
    "decide",
    "detection_probability",
    "falloff",
    "gaussian_likelihood",
    "initial_existence",
    "predict_existence",
    "range_bin",
    "repeat_rate",
    "see_through_q",
    "update_existence",
    "update_existence_persistent",
]


@dataclass(frozen=True)
class ExistenceConfig:
    """Parameters of the existence model (module doc); probabilities in [0, 1].

    pd_max: probability that the extractor reports a trunk that enough beams reach.
    min_beams: beams the extractor needs on a trunk (>= 1).
    gap_m: a return counts as in front of / beyond the trunk past this margin, m (>= 0).
    see_through_q: probability that a beam passes a real trunk's place (in (0, 1]).
    survival: probability that a real trunk is still there one scan later.
    max_range_m: no detection at or beyond this range (the sensor's), m.
    join_prob, remove_prob: the decisions' thresholds, remove_prob < join_prob.
    pd_range_m, pd_range_scale_m: the range fall-off of Pd (module doc; inf: none), m, m (> 0).
    see_through_k: the see-through tolerance's k-sigma (module doc; 0: none), >= 0.
    footprint_steps: a beam's angular footprint, in beam steps, that must lie inside the
        trunk for the beam to count as see-through (module doc, "Beam footprint"; 0: none).
    q_by_range, q_bin_m: see_through_q per range bin [i q_bin_m, (i + 1) q_bin_m), each in
        (0, 1] (module doc, "See-through rate by range"; (): see_through_q at every range), m.
    repeat_by_range, repeat_bin_m: persistent clutter's repeat_prob per range bin
        [i repeat_bin_m, (i + 1) repeat_bin_m), each in (0, 1), not scaled by the fall-off
        (module doc, "Repeat rate by range"; (): repeat_prob f(d) at every range), m.
    """

    pd_max: float = 0.9
    min_beams: int = 2
    gap_m: float = 0.3
    see_through_q: float = 0.1
    survival: float = 1.0
    max_range_m: float = 80.0
    join_prob: float = 0.99
    remove_prob: float = 0.01
    pd_range_m: float = math.inf
    pd_range_scale_m: float = 5.0
    see_through_k: float = 0.0
    footprint_steps: float = 0.0
    q_by_range: tuple[float, ...] = ()
    q_bin_m: float = 10.0
    repeat_by_range: tuple[float, ...] = ()
    repeat_bin_m: float = 10.0

    def __post_init__(self) -> None:
        for name in ("pd_max", "survival", "join_prob", "remove_prob"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and 0.0 <= v <= 1.0):
                raise ValueError(f"ExistenceConfig.{name}: must be in [0, 1], got {v!r}")
        if not (isinstance(self.see_through_q, (int, float)) and 0.0 < self.see_through_q <= 1.0):
            raise ValueError(
                f"ExistenceConfig.see_through_q: must be in (0, 1], got {self.see_through_q!r}"
            )
        if not (isinstance(self.min_beams, int) and self.min_beams >= 1):
            raise ValueError(
                f"ExistenceConfig.min_beams: must be an integer >= 1, got {self.min_beams!r}"
            )
        if not (isinstance(self.gap_m, (int, float)) and 0.0 <= self.gap_m < math.inf):
            raise ValueError(f"ExistenceConfig.gap_m: must be finite and >= 0, got {self.gap_m!r}")
        if not (isinstance(self.max_range_m, (int, float)) and self.max_range_m > 0):
            raise ValueError(f"ExistenceConfig.max_range_m: must be > 0, got {self.max_range_m!r}")
        if not self.remove_prob < self.join_prob:
            raise ValueError(
                f"ExistenceConfig.remove_prob: must be below join_prob ({self.join_prob!r}), "
                f"got {self.remove_prob!r}"
            )
        if not (isinstance(self.pd_range_m, (int, float)) and self.pd_range_m > 0):
            raise ValueError(
                f"ExistenceConfig.pd_range_m: must be > 0 (inf: no fall-off), got "
                f"{self.pd_range_m!r}"
            )
        v = self.pd_range_scale_m
        if not (isinstance(v, (int, float)) and 0.0 < v < math.inf):
            raise ValueError(f"ExistenceConfig.pd_range_scale_m: must be finite and > 0, got {v!r}")
        v = self.see_through_k
        if not (isinstance(v, (int, float)) and 0.0 <= v < math.inf):
            raise ValueError(f"ExistenceConfig.see_through_k: must be finite and >= 0, got {v!r}")
        v = self.footprint_steps
        if isinstance(v, bool) or not (isinstance(v, (int, float)) and 0.0 <= v < math.inf):
            raise ValueError(f"ExistenceConfig.footprint_steps: must be finite and >= 0, got {v!r}")
        self._check_rates("q_by_range", "q_bin_m", "]")
        self._check_rates("repeat_by_range", "repeat_bin_m", ")")

    def _check_rates(self, table: str, bin_name: str, top: str) -> None:
        """table: rates in (0, 1] (top "]") or (0, 1) (top ")"), kept as a tuple (the frozen
        config stays hashable when given a list); bin_name: finite and > 0."""
        v = getattr(self, table)
        if not isinstance(v, (tuple, list)) or not all(
            isinstance(p, (int, float))
            and not isinstance(p, bool)
            and 0.0 < p
            and (p <= 1.0 if top == "]" else p < 1.0)
            for p in v
        ):
            shown = repr(v) if len(repr(v)) <= 80 else repr(v)[:77] + "..."
            raise ValueError(f"ExistenceConfig.{table}: each must be in (0, 1{top}, got {shown}")
        object.__setattr__(self, table, tuple(float(p) for p in v))
        v = getattr(self, bin_name)
        if isinstance(v, bool) or not (isinstance(v, (int, float)) and 0.0 < v < math.inf):
            raise ValueError(f"ExistenceConfig.{bin_name}: must be finite and > 0, got {v!r}")


class BeamEvidence(NamedTuple):
    """Per landmark (L,) int64: beams reaching its width, of them occluded by a nearer return,
    and of them passing beyond it (no return or a farther one)."""

    reach: np.ndarray
    occluded: np.ndarray
    through: np.ndarray


def _wrap(a: np.ndarray) -> np.ndarray:
    return (a + np.pi) % (2.0 * np.pi) - np.pi


def beam_evidence(
    ranges_m: np.ndarray,
    bearings_rad: np.ndarray,
    lm_range_m: np.ndarray,
    lm_bearing_rad: np.ndarray,
    radius_m: np.ndarray,
    cfg: ExistenceConfig,
    bearing_sigma_rad: np.ndarray | float = 0.0,
    place_sigma: np.ndarray | None = None,
) -> BeamEvidence:
    """The beams of one scan (ranges_m (B,), NaN = no return; bearings_rad (B,), laser frame)
    that reach each landmark (lm_range_m, lm_bearing_rad, radius_m: (L,), laser frame) within
    its angular half-width asin(radius / range) (+ bearing_sigma_rad), and how many of them are
    occluded or pass through (module doc). place_sigma (L, 2): the sd of each landmark's
    predicted (range m, bearing rad), for the see-through tolerance (module doc; with
    cfg.see_through_k > 0; None or k 0: none). With cfg.footprint_steps > 0 a see-through beam's
    footprint must lie inside the trunk (module doc, "Beam footprint"; the beam step is that of
    bearings[0:2], a uniform grid)."""
    d = np.asarray(lm_range_m, dtype=np.float64)[:, None]
    a = np.asarray(radius_m, dtype=np.float64)[:, None]
    own = np.arcsin(np.clip(a / np.maximum(d, 1e-12), 0.0, 1.0))  # the trunk's own half-width
    half = own + np.asarray(bearing_sigma_rad, dtype=np.float64).reshape(-1, 1)
    db = _wrap(np.asarray(bearings_rad)[None, :] - np.asarray(lm_bearing_rad)[:, None])
    reach = np.abs(db) <= half  # (L, B)
    r = np.asarray(ranges_m, dtype=np.float64)[None, :]
    with np.errstate(invalid="ignore"):
        near = r < d - a - cfg.gap_m
        beyond = ~np.isfinite(r) | (r > d + a + cfg.gap_m)
    through = (reach & beyond).sum(axis=1).astype(np.int64)
    sig = None
    if place_sigma is not None and cfg.see_through_k > 0:
        sig = np.asarray(place_sigma, dtype=np.float64).reshape(-1, 2)
        edge = a + cfg.gap_m + cfg.see_through_k * sig[:, :1]  # the k-sigma region's depth
        wide = np.abs(db) <= half + cfg.see_through_k * sig[:, 1:]  # and its bearing span
        with np.errstate(invalid="ignore"):
            inside = wide & np.isfinite(r) & (np.abs(r - d) <= edge)
            beyond = ~np.isfinite(r) | (r > d + edge)
        through = np.where(inside.any(axis=1), 0, (reach & beyond).sum(axis=1)).astype(np.int64)
    if cfg.footprint_steps > 0:
        through = np.minimum(
            through, _inside_footprint(db, own, beyond, bearings_rad, cfg, sig=sig)
        )
    return BeamEvidence(
        reach.sum(axis=1).astype(np.int64), (reach & near).sum(axis=1).astype(np.int64), through
    )


def _inside_footprint(db, own, beyond, bearings_rad, cfg: ExistenceConfig, *, sig) -> np.ndarray:
    """(L,) the beams beyond each landmark whose footprint (cfg.footprint_steps beam steps
    either side, + k sd_b with the tolerance's sig) lies inside its own angular half-width
    asin(a / d), `own` (L, 1), not widened by the bearing uncertainty (module doc, "Beam
    footprint")."""
    b = np.asarray(bearings_rad, dtype=np.float64).ravel()
    if b.size < 2:
        raise ValueError(
            "beam_evidence: the beam footprint (cfg.footprint_steps > 0) needs the beam step, "
            f"from at least 2 bearings; got {b.size}"
        )
    step = abs(float(b[1] - b[0]))
    margin = cfg.footprint_steps * step
    if sig is not None:
        margin = margin + cfg.see_through_k * sig[:, 1:]
    return ((np.abs(db) + margin <= own) & beyond).sum(axis=1).astype(np.int64)


def detection_probability(
    ev: BeamEvidence, lm_range_m: np.ndarray, in_fov: np.ndarray, cfg: ExistenceConfig
) -> np.ndarray:
    """(L,) Pd: pd_max (times the range fall-off, if any) where at least min_beams reaching
    beams are not occluded, in the field of view and inside max_range_m; 0 elsewhere."""
    free = ev.reach - ev.occluded
    ok = (free >= cfg.min_beams) & np.asarray(in_fov, bool)
    ok &= np.asarray(lm_range_m, dtype=np.float64) < cfg.max_range_m
    f = falloff(lm_range_m, cfg)
    return np.where(ok, cfg.pd_max if f is None else cfg.pd_max * f, 0.0)


def falloff(lm_range_m: np.ndarray, cfg: ExistenceConfig) -> np.ndarray | None:
    """(L,) the range fall-off f(d) of Pd (module doc), or None without one (pd_range_m inf)."""
    if math.isinf(cfg.pd_range_m):
        return None
    d = np.asarray(lm_range_m, dtype=np.float64)
    x = np.clip((d - cfg.pd_range_m) / cfg.pd_range_scale_m, -700.0, 700.0)
    return 1.0 / (1.0 + np.exp(x))


def see_through_q(lm_range_m: np.ndarray, cfg: ExistenceConfig) -> np.ndarray:
    """(L,) the see-through rate q of landmarks at these ranges: q_by_range's bin (the last
    beyond the table), or see_through_q everywhere without a table (module doc)."""
    d = np.asarray(lm_range_m, dtype=np.float64)
    if not cfg.q_by_range:
        return np.full(d.shape, float(cfg.see_through_q))
    table = np.asarray(cfg.q_by_range, dtype=np.float64)
    return table[range_bin(d, cfg.q_bin_m, table.size)]


def repeat_rate(lm_range_m: np.ndarray, cfg: ExistenceConfig) -> np.ndarray:
    """(L,) persistent clutter's repeat rate of landmarks at these ranges from the
    repeat_by_range table (its bin; the last beyond the table; module doc, "Repeat rate by
    range"). An error without a table: the single repeat_prob is the map policy's."""
    if not cfg.repeat_by_range:
        raise ValueError("repeat_rate: cfg.repeat_by_range is empty (no table to read)")
    table = np.asarray(cfg.repeat_by_range, dtype=np.float64)
    return table[range_bin(lm_range_m, cfg.repeat_bin_m, table.size)]


def range_bin(range_m: np.ndarray, bin_m: float, n: int) -> np.ndarray:
    """(L,) int64 the range bin [i bin_m, (i + 1) bin_m) of each range, i = floor(range /
    bin_m) (Python's //, so that the filter and the derivation agree at every edge), clipped
    to 0 .. n - 1 (the last bin holds everything beyond; NaN lands in bin 0)."""
    d = np.nan_to_num(np.asarray(range_m, dtype=np.float64))
    return np.clip(np.floor_divide(d, float(bin_m)), 0, n - 1).astype(np.int64)


def clutter_density(false_per_scan: float, max_range_m: float, fov_rad: float) -> float:
    """Clutter density kappa, false detections per m per rad: the extractor's measured false
    detections per scan spread evenly over the measurement space [0, max_range] x fov."""
    if not (false_per_scan >= 0 and max_range_m > 0 and fov_rad > 0):
        raise ValueError(
            "clutter_density: needs false_per_scan >= 0, max_range_m > 0 and fov_rad > 0, got "
            f"{false_per_scan!r}, {max_range_m!r}, {fov_rad!r}"
        )
    return float(false_per_scan) / (float(max_range_m) * float(fov_rad))


def gaussian_likelihood(nu: np.ndarray, S: np.ndarray) -> np.ndarray:
    """(L,) N(nu; 0, S) of innovations nu (L, 2) [m, rad] with covariances S (L, 2, 2)."""
    nu = np.asarray(nu, dtype=np.float64)
    S = np.asarray(S, dtype=np.float64)
    m = np.einsum("li,li->l", nu, np.linalg.solve(S, nu[..., None])[..., 0])
    return np.exp(-0.5 * m) / (2.0 * np.pi * np.sqrt(np.linalg.det(S)))


def initial_existence(birth_density: float, kappa: float) -> float:
    """b / (b + kappa): the existence of a new tentative (module doc)."""
    if not (birth_density >= 0 and kappa >= 0 and birth_density + kappa > 0):
        raise ValueError(
            f"initial_existence: needs densities >= 0, not both 0, got {birth_density!r}, {kappa!r}"
        )
    return birth_density / (birth_density + kappa)


def predict_existence(r: np.ndarray, cfg: ExistenceConfig) -> np.ndarray:
    """r * survival."""
    return np.asarray(r, dtype=np.float64) * cfg.survival


def update_existence(
    r: np.ndarray,
    pd: np.ndarray,
    detected: np.ndarray,
    likelihood: np.ndarray,
    through: np.ndarray,
    kappa: float,
    cfg: ExistenceConfig,
    q: np.ndarray | None = None,
) -> np.ndarray:
    """(L,) the existence after one scan (module doc, step 3). likelihood: N(nu; 0, S) of the
    associated measurement where detected (ignored elsewhere); through: see-through beams;
    q: (L,) each landmark's see-through rate (`see_through_q`; None: cfg.see_through_q, an
    error when cfg.q_by_range is set)."""
    r = np.asarray(r, dtype=np.float64)
    pd = np.asarray(pd, dtype=np.float64)
    det = np.asarray(detected, bool)
    q = _see_through_rate(q, cfg, "update_existence")
    if det.any() and not kappa > 0:
        raise ValueError(
            f"update_existence: a detection needs clutter density kappa > 0, got {kappa!r}"
        )
    g = np.where(det, np.asarray(likelihood, dtype=np.float64), 0.0)
    yes_det, no_det = r * pd * g, (1.0 - r) * kappa
    pass_through = q ** np.asarray(through, dtype=np.float64)
    yes_miss, no_miss = r * (1.0 - pd) * pass_through, 1.0 - r
    yes = np.where(det, yes_det, yes_miss)
    no = np.where(det, no_det, no_miss)
    total = yes + no
    return np.where(total > 0, yes / np.where(total > 0, total, 1.0), r)


def update_existence_persistent(
    r: np.ndarray,
    pd: np.ndarray,
    detected: np.ndarray,
    likelihood: np.ndarray,
    likelihood_object: np.ndarray,
    through: np.ndarray,
    repeat_prob: float | np.ndarray,
    cfg: ExistenceConfig,
    falloff: np.ndarray | None = None,
    q: np.ndarray | None = None,
) -> np.ndarray:
    """(L,) the existence after one scan against persistent clutter (module doc, "Persistent
    clutter"): "not a tree" is an object at the landmark's place that the extractor reports
    again with probability repeat_prob in a scan whose beams reach it (pd > 0), its circle's
    centre spread by its shape (likelihood_object: N(nu; 0, S + the shape's covariance));
    "tree" is as `update_existence`. likelihood: N(nu; 0, S) where detected. falloff: (L,)
    the range fall-off f(d) that scales repeat_prob as it scales Pd (module doc; None: 1);
    repeat_prob may be (L,), each landmark's (`repeat_rate`, then falloff None).
    q: (L,) each landmark's see-through rate (`see_through_q`; None: cfg.see_through_q, an
    error when cfg.q_by_range is set)."""
    r = np.asarray(r, dtype=np.float64)
    pd = np.asarray(pd, dtype=np.float64)
    det = np.asarray(detected, bool)
    q = _see_through_rate(q, cfg, "update_existence_persistent")
    if not np.all((np.asarray(repeat_prob) > 0.0) & (np.asarray(repeat_prob) < 1.0)):
        raise ValueError(
            f"update_existence_persistent: repeat_prob must be in (0, 1), got {repeat_prob!r}"
        )
    g = np.where(det, np.asarray(likelihood, dtype=np.float64), 0.0)
    g0 = np.where(det, np.asarray(likelihood_object, dtype=np.float64), 0.0)
    pass_through = q ** np.asarray(through, dtype=np.float64)
    # neither hypothesis reports what the beams cannot reach (a detection has pd > 0: the
    # caller gives a paired landmark pd_max)
    repeat = np.where((pd > 0) | det, repeat_prob, 0.0)
    if falloff is not None:
        repeat = repeat * np.asarray(falloff, dtype=np.float64)
    yes = np.where(det, r * pd * g, r * (1.0 - pd) * pass_through)
    no = (1.0 - r) * np.where(det, repeat * g0, 1.0 - repeat)
    total = yes + no
    return np.where(total > 0, yes / np.where(total > 0, total, 1.0), r)


def _see_through_rate(q, cfg: ExistenceConfig, name: str):
    """The see-through rate the updates charge: the landmarks' q (L,), or cfg.see_through_q
    when none is given; an error when none is given but cfg.q_by_range is set."""
    if q is not None:
        return np.asarray(q, dtype=np.float64)
    if cfg.q_by_range:
        raise ValueError(
            f"{name}: cfg.q_by_range is set, so each landmark's q must be given "
            "(q=see_through_q(range, cfg)); got q=None, which would charge the single "
            "see_through_q"
        )
    return cfg.see_through_q


def decide(r: np.ndarray, cfg: ExistenceConfig) -> tuple[np.ndarray, np.ndarray]:
    """(join, remove), (L,) bool each: r >= join_prob, r < remove_prob."""
    r = np.asarray(r, dtype=np.float64)
    return r >= cfg.join_prob, r < cfg.remove_prob
