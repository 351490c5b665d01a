"""Victoria Park: the map policy's pruning settings, derived from scans 1-2000 only.

`trunkslam reproduce victoria-park-pruning` (needs the data; seconds) runs the preset with
pruning switched off over scans 1-2000 (published detections, IHGR) and measures, for every
landmark of the final map, how often the detector reported it when it was in view: the scans
where its position, seen from the run's pose, lay inside the laser's field of view, after the
scan it joined the map, against those where the filter associated a detection with it, by range
in 5 m bins. Established landmarks (associated in more than 30 scans: trees) and short-lived
ones (10 scans or fewer) are counted apart. No GPS error enters it, and scans 2001-7249 never
do. The rule (`derive`):

- `prune_range_m`: the end of the first run of bins where the established landmarks' detection
  rate is at least 0.5 (beyond it even trees are missed more often than seen); the run starts at
  the first such bin, so a nearest bin seen less often (trunks within a few metres pass the
  laser's side, half in view) does not leave the rule without a range;
- `prune_hit_ratio`: half the lowest established rate inside that run (a landmark reported at
  under half the rate of the worst-seen tree);
- `prune_after_expected`: the fewest expected scans n for which a tree at that lowest rate
  falls below the ratio by chance with probability at most 1% (binomial).
"""

from __future__ import annotations

import logging
import math

import numpy as np
from scipy.stats import binom

from experiments.errors import DataError, MissingDataError
from experiments.io.config_file import load_slam_config, preset_path
from experiments.io.victoria_park import load_victoria_park
from experiments.io.writers import write_tidy_table
from slam import SlamLog, run_slam, se2

__all__ = ["BIN_EDGES_M", "derive", "detection_rates", "run"]

log = logging.getLogger(__name__)

FIT_SCANS = 2000
BIN_EDGES_M = np.arange(0.0, 85.0, 5.0)
ESTABLISHED, SHORT_LIVED = 30, 10  # associated in more than / at most this many scans


def detection_rates(lg: SlamLog, laser_pose, fov: tuple[float, float]) -> dict[str, np.ndarray]:
    """Expected and detected counts per range bin (`BIN_EDGES_M`) for the established and the
    short-lived landmarks of a run: {"<kind>_expected": (B,), "<kind>_detected": (B,)}."""
    seen = set(zip(lg.obs_scan.tolist(), lg.obs_landmark.tolist()))
    n_bins = BIN_EDGES_M.size - 1
    out = {}
    for kind, sel in (
        ("established", lg.landmark_n_obs > ESTABLISHED),
        ("short_lived", lg.landmark_n_obs <= SHORT_LIVED),
    ):
        ids, xy, first = lg.landmark_id[sel], lg.landmark_xy[sel], lg.landmark_first_scan[sel]
        expected, detected = np.zeros(n_bins, np.int64), np.zeros(n_bins, np.int64)
        for k in range(lg.n_scans):
            z, _ = se2.observe(lg.pose[k], xy, laser_pose)
            b = np.digitize(z[:, 0], BIN_EDGES_M) - 1
            inside = (z[:, 1] >= fov[0]) & (z[:, 1] <= fov[1]) & (first < k)
            inside &= (b >= 0) & (b < n_bins)
            for j in np.flatnonzero(inside):
                expected[b[j]] += 1
                detected[b[j]] += (k, int(ids[j])) in seen
        out[f"{kind}_expected"], out[f"{kind}_detected"] = expected, detected
    return out


def derive(rates: dict[str, np.ndarray], min_rate: float = 0.5, risk: float = 0.01) -> dict:
    """The pruning settings from the detection rates (module docstring)."""
    e, d = rates["established_expected"], rates["established_detected"]
    rate = np.where(e > 0, d / np.maximum(e, 1), np.nan)
    good = np.flatnonzero(rate >= min_rate)
    if not good.size:
        raise DataError(
            "victoria-park-pruning: the established landmarks are seen in under half the scans "
            "in which they are in view in every range bin: no range to prune within"
        )
    first = n_in = int(good[0])  # nearer bins seen less often (trunks passing the laser's side)
    while n_in < rate.size and rate[n_in] >= min_rate:
        n_in += 1
    p_min = float(np.min(rate[first:n_in]))
    ratio = p_min / 2
    n = next(
        n
        for n in range(1, 1000)
        if binom.cdf(math.ceil(ratio * n) - 1, n, p_min) <= risk  # P(hits < ratio n)
    )
    return {
        "prune_range_m": float(BIN_EDGES_M[n_in]),
        "prune_hit_ratio": round(ratio, 3),
        "prune_after_expected": int(n),
        "lowest_established_rate": p_min,
    }


def run(ctx) -> None:
    """The registered experiment `victoria-park-pruning`."""
    try:
        seq = load_victoria_park(n_scans=1000 if ctx.quick else FIT_SCANS)
    except MissingDataError as exc:
        log.warning("Victoria Park pruning skipped: %s", exc)
        ctx.config["victoria-park-pruning"] = f"skipped: {exc}"
        return
    cfg = load_slam_config(preset_path("victoria_park_ute"))
    cfg = cfg.with_(**{"map_policy.prune_after_expected": 0})
    lg = run_slam(seq, cfg, features="detections", association="ihgr")
    a0 = float(seq.scan_angle_min)
    fov = (a0, a0 + float(seq.scan_angle_increment) * (seq.n_beams - 1))
    rates = detection_rates(lg, lg.laser_pose, fov)
    derived = derive(rates)
    ctx.config["victoria-park-pruning"] = {"scans": seq.n_scans, **derived}
    records = []
    for kind in ("established", "short_lived"):
        e, d = rates[f"{kind}_expected"], rates[f"{kind}_detected"]
        for b in range(e.size):
            if e[b]:
                records.append(
                    {
                        "landmarks": kind,
                        "range_from_m": float(BIN_EDGES_M[b]),
                        "range_to_m": float(BIN_EDGES_M[b + 1]),
                        "expected": int(e[b]),
                        "detected": int(d[b]),
                        "rate": float(d[b] / e[b]),
                    }
                )
    n_est = int(np.sum(lg.landmark_n_obs > ESTABLISHED))
    n_short = int(np.sum(lg.landmark_n_obs <= SHORT_LIVED))
    ctx.outputs += write_tidy_table(
        ctx.out_dir / "victoria_park_pruning",
        records,
        index=["range_from_m", "range_to_m"],
        columns=["landmarks"],
        values=["expected", "detected", "rate"],
        title=(
            "Victoria Park: how often the detector reports a landmark in view "
            f"(scans 1-{seq.n_scans})"
        ),
        notes=(
            f"The preset without pruning, published detections, IHGR; {lg.landmark_id.size} "
            f"landmarks, {n_est} established (associated in more than {ESTABLISHED} scans), "
            f"{n_short} short-lived ({SHORT_LIVED} or fewer). Expected: in the field of view, "
            "after the scan it joined the map. Derived (experiments/paper/vp_pruning.py): "
            f"prune_range_m = {derived['prune_range_m']:g}, prune_hit_ratio = "
            f"{derived['prune_hit_ratio']:g}, prune_after_expected = "
            f"{derived['prune_after_expected']} (lowest established rate within range "
            f"{derived['lowest_established_rate']:.3f})."
        ),
    )
